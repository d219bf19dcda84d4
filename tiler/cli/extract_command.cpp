// `isotile extract INPUT -o OUT [...]`: the arguments turned into the library's pipeline
// (tiler/pipeline.h), whose statistics go to --stats; --render draws the result; under an MPI
// launcher an out-of-core run goes distributed (tiler/mpi_extract.h).
#include "tiler/cli/commands.h"

#include <cctype>
#include <cmath>
#include <cstdlib>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "tiler/brick_plan.h"
#include "tiler/pipeline.h"
#include "tiler/render_command.h"
#include "tiler/source_histogram.h"
#include "tiler/volume_source.h"

namespace isotile::cli {

namespace {

using json = StatsJson;

Method parse_method(const std::string& s) {
  if (s == "mc") return Method::MarchingCubes;
  if (s == "macet") return Method::Macet;
  return Method::DualContouring;
}

Backend parse_backend(const std::string& s) {
  if (s == "cpu") return Backend::Cpu;
  if (s == "gs") return Backend::GeometryShader;
  if (s == "hp") return Backend::HistoPyramid;
  return Backend::Auto;
}

#ifdef ISOTILE_HAVE_MPI
// A distributed run's keys besides the single-process ones (docs/cli.md): every rank's times
// and bricks, the load imbalance, and each brick's measured seconds per pass.
json distributed_json(const DistributedResult& d) {
  json j;
  j["ranks"] = d.ranks;
  json per_rank = json::array();
  double rss = 0;
  for (const RankTimes& t : d.rank_times) {
    per_rank.push_back({{"seconds_count", t.seconds_count},
                        {"seconds_extract", t.seconds_extract},
                        {"bricks_counted", t.bricks_counted},
                        {"bricks_extracted", t.bricks_extracted},
                        {"triangles", t.triangles},
                        {"planned_cost", t.planned_cost},
                        {"peak_rss_mb", t.peak_rss_mb}});
    rss = std::max(rss, t.peak_rss_mb);
  }
  j["per_rank"] = per_rank;
  j["load_imbalance"] = d.load_imbalance;
  j["load_imbalance_planned"] = d.planned_imbalance;
  j["brick_seconds"] = {{"count", d.brick_seconds_count}, {"extract", d.brick_seconds_extract}};
  j["brick_faces"] = d.brick_faces;
  j["peak_rss_mb"] = rss;  // the largest rank's
  return j;
}
#endif

// The arguments as the pipeline's options (checked by the pipeline, which names the flags).
PipelineOptions pipeline_options(const ExtractArgs& args) {
  PipelineOptions o;
  ExtractOptions& e = o.extract;
  e.method = parse_method(args.method);
  e.backend = parse_backend(args.backend);
  e.normals = args.normals;
  e.dc_solver = args.dc_solver == "particle" ? DcSolver::Particle
                : args.dc_solver == "qef"    ? DcSolver::Qef
                                             : DcSolver::MassPoint;
  e.keep_quads = args.quads;
  e.dc_hermite = args.dc_hermite == "eno" ? DcHermite::Eno : DcHermite::Central;
  e.dc_vertices = args.dc_vertices == "cell" ? DcVertices::Cell : DcVertices::Patch;
  e.quality = args.quality == "max" ? MacetQuality::Max : MacetQuality::Fast;
  e.macet_relax = args.macet_relax;
  for (const std::string& name : args.given) check_option_method(name, e.method);
  o.world_frame = args.frame == "world";
  o.simplify = args.simplify;
  // A GL backend named by --backend makes its context on a thread of its own from here on, while
  // the volume is read (its checks below then wait for nothing; core/extract/extract.h).
  start_backend(e.backend);
  // Their errors come before a malformed --iso's, as they always have.
  check_pipeline_options(o);
  o.iso_auto = args.iso == "auto";
  if (!args.iso.empty() && !o.iso_auto) {
    char* end = nullptr;
    const double iso = std::strtod(args.iso.c_str(), &end);
    // No blank before it either (strtod passes over those), as none is taken after it.
    if (end == args.iso.c_str() || *end != '\0' || !std::isfinite(iso) ||
        std::isspace(static_cast<unsigned char>(args.iso.front())))
      throw InputError("--iso must be a finite number or 'auto', got '" + args.iso + "'");
    o.iso = iso;
  }
  o.check_intersections = args.check_intersections;
  o.allow_empty = args.allow_empty;
  o.memory = args.memory;
  o.output = args.output;
  o.ascii = args.ascii;
  o.stats = !args.stats.empty();
  o.keep_mesh = false;
  o.progress = &g_progress;
  o.log = progress;
  return o;
}

#ifdef ISOTILE_HAVE_MPI
// Out of core on several MPI ranks: every rank reads the bricks it extracts and writes their
// records into the one output file (tiler/mpi_extract.h).
int run_extract_distributed(const ExtractArgs& args, PipelineOptions o, Clock::time_point t_total) {
  // The pipeline's checks, in its order, before any rank reads.
  check_output(o.output, o.simplify >= 1);
  const MeshFormat format = mesh_format_from_path(o.output);
  const ExtractOptions e = pipeline_extract_options({.path = args.in.input, .raw = {}}, o);
  TiledOptions to = tiled_options(o, e, format);
  json auto_iso;
  // Every rank reads the whole input once for the histogram and finds the same value.
  if (o.iso_auto)
    auto_iso = choose_isovalue(
        source_histogram(*open_volume_source(args.in.input, args.in.raw_options(), to.memory),
                         to.memory),
        to.extract.iso, progress);
  progress("extracting " + args.in.input + " brick by brick within " + args.memory + " on " +
           std::to_string(g_mpi->size) +
           " MPI ranks (the progress lines count rank 0's share of the bricks)");
  g_distributed = true;
  const DistributedResult d =
      extract_distributed(args.in.input, args.in.raw_options(), to, o.world_frame, args.output);
  g_distributed = false;
  if (g_mpi->rank != 0) return 0;
  const TiledResult& r = d.tiled;
  progress(tiled_summary(r, to.simplify < 1));
  if (!args.stats.empty()) {
    json j = tiled_stats({.input = args.in.input,
                          .output = args.output,
                          .dims = d.dims,
                          .type = d.type,
                          .extract = &to.extract,
                          .auto_iso = auto_iso,
                          .result = &r,
                          // the ranks wrote the mesh in the frame they found
                          .world_frame = d.world_frame,
                          .memory = to.memory,
                          .region_reads = !d.source_in_memory,
                          .simplify = to.simplify,
                          .seconds_total = seconds_since(t_total)});
    j.update(distributed_json(d));
    write_text(args.stats, j.dump(2) + "\n");
  }
  if (!args.render.empty()) render_extracted_file(args.output, args.render, g_quiet);
  progress("done in " + fmt_seconds(seconds_since(t_total)));
  return 0;
}
#endif

}  // namespace

CLI::App* add_extract_command(CLI::App& app, ExtractArgs& ex) {
  auto* extract_cmd = app.add_subcommand("extract", "Extract an isosurface mesh from a volume");
  ex.in.add_to(*extract_cmd);
  extract_cmd
      ->add_option("-o,--output", ex.output,
                   "Output mesh: .ply (binary; --ascii for text), .obj, .stl (binary) or .off")
      ->required();
  extract_cmd
      ->add_option(
          "--iso", ex.iso,
          "Isovalue; samples >= iso are inside. A finite number, or auto: Otsu's threshold of "
          "the samples' histogram, printed with their range. Required for files; fields default "
          "to their own (0; 0.5 for marschner-lobb)")
      ->check(non_empty());
  extract_cmd->add_flag("--allow-empty", ex.allow_empty,
                        "Write the empty mesh (exit 0) when no pair of samples straddles the "
                        "isovalue, instead of failing with the samples' range");
  extract_cmd->add_option("--method", ex.method, "Extraction method")
      ->check(CLI::IsMember({"mc", "macet", "dc"}));
  extract_cmd->add_option("--backend", ex.backend, "Where to run it")
      ->check(CLI::IsMember({"cpu", "gs", "hp", "auto"}));
  extract_cmd
      ->add_option("--stats", ex.stats,
                   "Write statistics as JSON to this file, any name ('-': stdout; default: none)")
      ->check(non_empty());
  extract_cmd->add_flag("--normals", ex.normals, "Compute vertex normals (PLY and OBJ store them)");
  extract_cmd->add_flag("--ascii", ex.ascii, "ASCII PLY instead of binary");
  extract_cmd
      ->add_option("--dc-solver", ex.dc_solver,
                   "Dual Contouring vertex placement: mass (mass point, best triangles), "
                   "particle (the paper's minimizer, 10 steps), qef (truncated SVD)")
      ->check(CLI::IsMember({"mass", "particle", "qef"}));
  extract_cmd
      ->add_option(
          "--dc-hermite", ex.dc_hermite,
          "Dual Contouring's Hermite data: central (central-difference normals, linear "
          "crossings; default) or eno (kink-aware crossings and one-sided normals: sharper "
          "edges and corners)")
      ->check(CLI::IsMember({"central", "eno"}));
  extract_cmd
      ->add_option("--dc-vertices", ex.dc_vertices,
                   "Dual Contouring's vertices: patch (one per surface patch of a cell: a "
                   "manifold mesh; default) or cell (one per cell, the paper's table: "
                   "non-manifold edges where a cell holds several sheets)")
      ->check(CLI::IsMember({"patch", "cell"}));
  extract_cmd
      ->add_option("--quality", ex.quality,
                   "Macet: fast (closed-form end-point push, default) or max (adds a local "
                   "search for the worst triangles; much slower)")
      ->check(CLI::IsMember({"fast", "max"}));
  extract_cmd
      ->add_option("--macet-relax", ex.macet_relax,
                   "Macet: move samples pinned in one-sample-thin features away from the "
                   "isovalue so that their crossings lie at least this far (edge lengths, "
                   "0 to 0.5, default 0: off); the surface moves by at most as much there and "
                   "their slivers go (docs/macet.md)")
      ->check(CLI::Validator(
          [](std::string& s) {
            char* end = nullptr;
            const double v = std::strtod(s.c_str(), &end);
            const bool ok = end != s.c_str() && *end == '\0' && v >= 0 && v < 0.5;
            return ok ? std::string() : "must be a number in [0, 0.5), got '" + s + "'";
          },
          "in [0, 0.5)"));
  extract_cmd->add_flag(
      "--quads", ex.quads,
      "Dual Contouring: keep quads (PLY, OBJ and OFF polygons; not STL) instead of "
      "splitting");
  extract_cmd->add_flag("--check-intersections", ex.check_intersections,
                        "Count self-intersecting triangle pairs (stats key self_intersections)");
  extract_cmd
      ->add_option("--simplify", ex.simplify,
                   "Simplify the mesh to this fraction of its faces (0 < R <= 1; 1: off), keeping "
                   "its topology, its border and well-shaped triangles (see `isotile simplify`)")
      ->check(positive_number(1, "a number in (0, 1]"));
  extract_cmd
      ->add_option("--frame", ex.frame,
                   "Mesh coordinates: world (default; the file's orientation, LPS for medical "
                   "images) or grid (origin + spacing x index, no direction cosines)")
      ->check(CLI::IsMember({"world", "grid"}));
  extract_cmd
      ->add_option("--memory", ex.memory,
                   "Out of core: extract brick by brick, each brick's working set within SIZE "
                   "(e.g. 256MiB, 2GB), streaming the mesh to a binary PLY or STL file identical "
                   "to an in-core run (default: in core)")
      ->check(non_empty());
  extract_cmd
      ->add_option("--render", ex.render,
                   "Also draw the mesh to this PNG picture (as `isotile render MESH -o PICTURE` "
                   "with its defaults)")
      ->check(non_empty());
  // Which method-specific options were given (pipeline_options() refuses them with another
  // method).
  extract_cmd->parse_complete_callback([&ex, extract_cmd] {
    ex.given.clear();
    for (const char* name :
         {"--quality", "--dc-solver", "--dc-hermite", "--dc-vertices", "--quads"})
      if (extract_cmd->count(name) > 0) ex.given.push_back(name);
  });
  return extract_cmd;
}

int run_extract(const ExtractArgs& args) {
  const auto t_total = Clock::now();
  keep_freed_memory_for_reuse();
  start_worker_threads();
  // Fail on a bad output name or an unavailable method before spending time on reading (the
  // pipeline checks the output again, as every caller's).
  check_output(args.output, !args.memory.empty() && args.simplify >= 1);
  mesh_output_format(args.output, args.ascii);
  if (!args.stats.empty() && args.stats != "-") check_output(args.stats);
  check_distinct_files({{"the input", args.in.input},
                        {"the output", args.output},
                        {"--stats", args.stats},
                        {"--render", args.render}},
                       1);
  PipelineInput input;
  input.path = args.in.input;
  input.raw = args.in.raw_options();  // --dims, --spacing, ... checked before anything is read
  if (!args.render.empty()) check_picture_path(args.render);
  PipelineOptions options = pipeline_options(args);
#ifdef ISOTILE_HAVE_MPI
  if (g_mpi && !args.memory.empty()) return run_extract_distributed(args, options, t_total);
#endif
  // In core, --render draws the mesh as written; out of core, from the file.
  if (!args.render.empty() && args.memory.empty())
    options.written = [&](const Mesh& mesh) { render_extracted(mesh, args.render, g_quiet); };
  const PipelineResult r = run_pipeline(input, options);
  if (!args.stats.empty()) write_text(args.stats, r.stats.dump(2) + "\n");
  if (!args.render.empty() && !args.memory.empty())
    render_extracted_file(args.output, args.render, g_quiet);
  progress("done in " + fmt_seconds(seconds_since(t_total)));
  return 0;
}

}  // namespace isotile::cli
