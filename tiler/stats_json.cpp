#include "tiler/stats_json.h"

#include <algorithm>
#include <cstdio>

#include <sys/resource.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "core/mesh/surface_distance.h"

namespace isotile {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string fmt_seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f s", s);
  return buf;
}

StatsJson quality_json(const QualityStats& q) {
  StatsJson j;
  const auto measured = [&](double v) {
    return q.triangles > 0 ? StatsJson(v) : StatsJson(nullptr);
  };
  j["radius_ratio_min"] = measured(q.min);
  j["radius_ratio_mean"] = measured(q.mean);
  j["radius_ratio_q001"] = measured(q.q001);
  j["radius_ratio_q01"] = measured(q.q01);
  j["radius_ratio_median"] = measured(q.median);
  j["radius_ratio_histogram"] = q.histogram;
  j["degenerate_triangles"] = q.degenerate;
  return j;
}

StatsJson topology_json(const TopologyStats& t, bool border_known) {
  StatsJson j;
  j["boundary_edges"] = t.boundary_edges;
  // Without the volume's box (a mesh read from a file) there is no border to count edges on.
  j["border_boundary_edges"] =
      border_known ? StatsJson(t.border_boundary_edges) : StatsJson(nullptr);
  j["nonmanifold_edges"] = t.nonmanifold_edges;
  j["nonmanifold_vertices"] = t.nonmanifold_vertices;
  j["inconsistently_oriented_edges"] = t.inconsistently_oriented_edges;
  j["euler"] = t.euler;
  j["components"] = t.components;
  j["closed"] = t.faces > 0 ? StatsJson(t.closed) : StatsJson(nullptr);
  j["watertight"] = border_known && t.faces > 0 ? StatsJson(t.watertight) : StatsJson(nullptr);
  return j;
}

StatsJson mesh_measures_json(const Mesh& mesh, const QualityStats& q, const TopologyStats& t,
                             std::optional<std::uint64_t> crossing) {
  StatsJson j;
  j["triangles"] = q.triangles;
  j["vertices"] = mesh.positions.size();
  j.update(quality_json(q));
  j.update(topology_json(t, false));
  j["edges"] = t.edges;
  j["unreferenced_vertices"] = t.unreferenced_vertices;
  if (crossing) j["self_intersections"] = *crossing;
  return j;
}

StatsJson simplify_json(const SimplifyStats& s, const Mesh& before, const Mesh& after,
                        const Vec3d& scale) {
  StatsJson j;
  j["triangles_before"] = s.faces_before;
  j["simplify_target_faces"] = s.target_faces;
  j["simplify_regions"] = s.regions;
  j["simplify_seam_regions"] = s.seam_regions;
  j["simplify_collapses"] = s.collapses;
  j["simplify_flips"] = s.flips;
  j["simplify_relaxed"] = s.relaxed;
  j["simplify_boundary_vertices"] = s.boundary_vertices;
  j["simplify_split_vertices"] = s.split_vertices;
  j["simplify_split_copies"] = s.split_copies;
  j["simplify_unlinked_faces"] = s.unlinked_faces;
  const std::optional<SurfaceDistance> distance = surface_distance(before, after, {.scale = scale});
  if (!distance) {  // a mesh without a face of non-zero area: no distance to say
    for (const char* key : {"simplify_hausdorff_mean", "simplify_hausdorff_max",
                            "simplify_hausdorff_max_at", "simplify_hausdorff_max_direction"})
      j[key] = nullptr;
    return j;
  }
  const SurfaceDistance& d = *distance;
  j["simplify_hausdorff_mean"] = d.mean();
  j["simplify_hausdorff_max"] = d.max();
  const OneWayDistance& worst = d.a_to_b.max >= d.b_to_a.max ? d.a_to_b : d.b_to_a;
  j["simplify_hausdorff_max_at"] = {worst.max_at[0] / scale[0], worst.max_at[1] / scale[1],
                                    worst.max_at[2] / scale[2]};
  j["simplify_hausdorff_max_direction"] =
      d.a_to_b.max >= d.b_to_a.max ? "input to result" : "result to input";
  return j;
}

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

// The threads that ran: the process's limit (--threads), or fewer where the machine has fewer
// cores (TBB's arenas run at most one thread per core).
int stats_threads() {
  return static_cast<int>(std::min<std::size_t>(
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism),
      static_cast<std::size_t>(tbb::this_task_arena::max_concurrency())));
}

}  // namespace isotile
