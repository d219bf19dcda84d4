// `isotile simplify IN OUT --ratio R | --faces N | --max-error E`.
#include "tiler/cli/commands.h"

#include <tbb/parallel_for.h>
#include <cmath>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <vector>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/simplify/simplify.h"
#include "tiler/stats_json.h"

namespace isotile::cli {

using json = StatsJson;

namespace {

SimplifyOptions simplify_options(double ratio, std::uint64_t faces, double max_error,
                                 double min_quality, bool relax) {
  SimplifyOptions o;
  o.ratio = ratio;
  o.faces = faces;
  o.max_error = max_error;
  o.min_quality = min_quality;
  o.relax = relax;
  o.progress = &g_progress;
  return o;
}

}  // namespace

CLI::App* add_simplify_command(CLI::App& app, SimplifyArgs& sa) {
  auto* simplify_cmd = app.add_subcommand(
      "simplify",
      "Simplify a mesh by edge collapses: fewer triangles, same topology and border, good shapes");
  simplify_cmd->add_option("IN", sa.input, "Mesh file (.ply, .obj, .stl, .off)")->required();
  simplify_cmd
      ->add_option("OUT", sa.output,
                   "Simplified mesh: .ply (binary; --ascii for text), .obj, .stl (binary) or .off")
      ->required();
  auto* ratio_opt =
      simplify_cmd->add_option("--ratio", sa.ratio, "Fraction of faces kept, in (0, 1]");
  auto* faces_opt =
      simplify_cmd->add_option("--faces", sa.faces, "Number of faces to keep (at least 1)");
  auto* error_opt = simplify_cmd->add_option(
      "--max-error", sa.max_error,
      "Simplify as far as the surface stays within E (mesh units) of the input: its "
      "vertices, edge midpoints and face centroids within E of the result (docs/simplify.md)");
  ratio_opt->check(positive_number(1, "a number in (0, 1]"));
  faces_opt->check(positive_number(1.8e19, "a whole number of faces, at least 1", true));
  error_opt->check(positive_number(HUGE_VAL, "a distance above 0"));
  // Exactly one of the three is given: none has a default.
  for (CLI::Option* o : {ratio_opt, faces_opt, error_opt}) o->default_str("");
  ratio_opt->excludes(faces_opt)->excludes(error_opt);
  faces_opt->excludes(error_opt);
  // None of them is a usage error too (exit 2, as two of them are), not a failed run.
  simplify_cmd->parse_complete_callback([=] {
    if (ratio_opt->count() + faces_opt->count() + error_opt->count() == 0)
      throw CLI::ValidationError("give one of --ratio, --faces and --max-error");
  });
  simplify_cmd
      ->add_option("--min-quality", sa.min_quality,
                   "Radius ratio (0..1) below which collapses may not create triangles (default "
                   "0.3)")
      ->check(CLI::Range(0.0, 1.0));
  simplify_cmd->add_flag("--no-relax", sa.no_relax, "Skip the flips and tangential relaxation");
  simplify_cmd->add_flag("--ascii", sa.ascii, "ASCII PLY instead of binary");
  simplify_cmd
      ->add_option("--stats", sa.stats,
                   "Write statistics as JSON to this file, any name ('-': stdout; "
                   "default: none)")
      ->check(non_empty());
  return simplify_cmd;
}

int run_simplify(const SimplifyArgs& args) {
  const auto t_total = Clock::now();
  check_output(args.output);
  const MeshFormat format = mesh_output_format(args.output, args.ascii);
  if (!args.stats.empty() && args.stats != "-") check_output(args.stats);
  check_distinct_files(
      {{"the input", args.input}, {"the output", args.output}, {"--stats", args.stats}}, 1);
  if ((args.ratio > 0) + (args.faces > 0) + (args.max_error > 0) != 1)
    throw InputError("give exactly one of --ratio, --faces and --max-error");
  progress("reading " + args.input);
  auto t0 = Clock::now();
  Mesh mesh = read_mesh(args.input);
  const double t_read = seconds_since(t0);
  progress("read " + std::to_string(mesh.triangles.size() + 2 * mesh.quads.size()) +
           " triangles, " + std::to_string(mesh.positions.size()) + " vertices in " +
           fmt_seconds(t_read));
  t0 = Clock::now();
  SimplifyStats sstats;
  Mesh out = simplify(
      mesh,
      simplify_options(args.ratio, args.faces, args.max_error, args.min_quality, !args.no_relax),
      &sstats);
  const double t_simplify = seconds_since(t0);
  progress("simplified to " + std::to_string(out.triangles.size()) + " triangles in " +
           fmt_seconds(t_simplify));
  if (const std::string missed = target_missed(sstats); !missed.empty()) say_warning({}, missed);
  progress("writing " + args.output);
  t0 = Clock::now();
  write_mesh(
      out, args.output,
      {.format = format, .ascii = args.ascii, .write_normals = true, .progress = &g_progress});
  const double t_write = seconds_since(t0);
  const double t_done = seconds_since(t_total);
  if (!args.stats.empty()) {
    t0 = Clock::now();
    json j;
    j["input"] = args.input;
    j["output"] = args.output;
    j["threads"] = stats_threads();
    j["triangles"] = out.triangles.size();
    j["vertices"] = out.positions.size();
    j.update(quality_json(triangle_quality(out)));
    j.update(topology_json(mesh_topology(out), false));
    j.update(simplify_json(sstats, mesh, out, {1, 1, 1}));
    j["seconds"] = {{"read", t_read},
                    {"simplify", t_simplify},
                    {"write", t_write},
                    {"total", t_done},
                    {"measure", seconds_since(t0)}};
    j["peak_rss_mb"] = peak_rss_mb();
    write_text(args.stats, j.dump(2) + "\n");
  }
  progress("done in " + fmt_seconds(t_done));
  return 0;
}

}  // namespace isotile::cli
