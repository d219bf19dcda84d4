// `isotile quality MESH [--json]`: the measures of a mesh file.
#include "tiler/cli/commands.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <vector>

#include "core/errors.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/mesh/self_intersections.h"
#include "core/mesh/surface_distance.h"
#include "tiler/stats_json.h"

namespace isotile::cli {

using json = StatsJson;

CLI::App* add_quality_command(CLI::App& app, QualityArgs& args) {
  auto* quality_cmd = app.add_subcommand(
      "quality", "Measure a mesh: radius ratios, boundary, manifoldness, Euler characteristic");
  quality_cmd->add_option("MESH", args.path, "Mesh file (.ply, .obj, .stl, .off)")->required();
  quality_cmd->add_flag("--json", args.json, "Print JSON");
  quality_cmd->add_flag("--check-intersections", args.check_intersections,
                        "Count self-intersecting triangle pairs");
  quality_cmd->add_option("--reference", args.reference,
                          "Also measure the two-way sampled (Hausdorff) distance to this mesh "
                          "(.ply, .obj, .stl, .off), e.g. the input of a simplification (mesh "
                          "units; default: none)");
  return quality_cmd;
}

int run_quality(const QualityArgs& args) {
  const std::string& path = args.path;
  const bool as_json = args.json;
  const bool check_intersections = args.check_intersections;
  const std::string& reference = args.reference;
  const Mesh mesh = read_mesh(path);
  const QualityStats q = triangle_quality(mesh);
  const TopologyStats t = mesh_topology(mesh);
  std::optional<std::uint64_t> crossing;
  if (check_intersections) crossing = self_intersections(mesh).pairs;
  json j;
  j["mesh"] = path;
  j.update(mesh_measures_json(mesh, q, t, crossing));
  std::optional<SurfaceDistance> distance;
  if (!reference.empty()) {
    distance = surface_distance(read_mesh(reference), mesh);
    if (!distance)
      throw InputError("--reference: the distance between " + reference + " and " + path +
                       " needs a face of non-zero area in each");
    j["reference"] = reference;
    j["hausdorff_mean"] = distance->mean();
    j["hausdorff_max"] = distance->max();
    j["hausdorff_reference_to_mesh"] = {{"mean", distance->a_to_b.mean},
                                        {"max", distance->a_to_b.max},
                                        {"samples", distance->a_to_b.samples}};
    j["hausdorff_mesh_to_reference"] = {{"mean", distance->b_to_a.mean},
                                        {"max", distance->b_to_a.max},
                                        {"samples", distance->b_to_a.samples}};
  }
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("mesh                  %s\n", path.c_str());
  std::printf("vertices / triangles  %zu / %llu\n", mesh.positions.size(),
              static_cast<unsigned long long>(q.triangles));
  if (q.triangles == 0)  // no value to say (the JSON says null), not the zeros of no triangles
    std::printf("radius ratio          n/a (no triangles)\n");
  else
    std::printf("radius ratio          min %.4g  q0.1%% %.4g  q1%% %.4g  mean %.4f  median %.4f\n",
                q.min, q.q001, q.q01, q.mean, q.median);
  std::printf("degenerate triangles  %llu\n", static_cast<unsigned long long>(q.degenerate));
  std::printf("boundary edges        %llu\n", static_cast<unsigned long long>(t.boundary_edges));
  std::printf("non-manifold          %llu edges, %llu vertices\n",
              static_cast<unsigned long long>(t.nonmanifold_edges),
              static_cast<unsigned long long>(t.nonmanifold_vertices));
  std::printf("orientation           %llu inconsistent edges\n",
              static_cast<unsigned long long>(t.inconsistently_oriented_edges));
  std::printf("euler / components    %lld / %llu\n", static_cast<long long>(t.euler),
              static_cast<unsigned long long>(t.components));
  std::printf("closed                %s\n", t.faces == 0 ? "n/a (no faces)"
                                            : t.closed   ? "yes"
                                                         : "no");
  std::printf(
      "watertight            cannot tell: a mesh file carries no volume box (isotile "
      "extract --stats can)\n");
  if (crossing)
    std::printf("self-intersections    %llu triangle pairs\n",
                static_cast<unsigned long long>(*crossing));
  if (distance)
    std::printf(
        "distance to reference mean %.4g  max %.4g (reference to mesh: mean %.4g max %.4g; "
        "mesh to reference: mean %.4g max %.4g)\n",
        distance->mean(), distance->max(), distance->a_to_b.mean, distance->a_to_b.max,
        distance->b_to_a.mean, distance->b_to_a.max);
  return 0;
}

}  // namespace isotile::cli
