// The pieces of the statistics JSON that `isotile extract --stats`, `simplify --stats` and
// `quality --json` share (docs/cli.md lists the keys): built in the library, so that every way in
// (the CLI, Python, the MeshLab plugin) reports the same keys with the same values.
#pragma once

#include <chrono>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "core/mesh/mesh.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/simplify/simplify.h"
#include "core/volume/volume.h"

namespace isotile {

using StatsJson = nlohmann::ordered_json;

// radius_ratio_* and degenerate_triangles. A measure without a value (the radius ratios of no
// triangle) is null, never a made-up 0.
StatsJson quality_json(const QualityStats& q);

// Edge and component counts, closed and watertight. `border_known`: the mesh's volume box is
// known (an extraction); a mesh read from a file has none, so whether its boundary lies on a
// volume border cannot be told: watertight is null. A mesh without faces is neither closed nor
// open: both are null.
StatsJson topology_json(const TopologyStats& t, bool border_known);

// What `isotile quality --json` reports of a mesh without its volume (a file, arrays): its
// triangle and vertex counts, quality_json, topology_json without a border, `edges`,
// `unreferenced_vertices`, and `self_intersections` where `crossing` holds their count.
StatsJson mesh_measures_json(const Mesh& mesh, const QualityStats& q, const TopologyStats& t,
                             std::optional<std::uint64_t> crossing);

// Keys of a simplification; `scale` turns mesh units into voxels where known. Measures the
// two-way distance between `before` and `after`.
StatsJson simplify_json(const SimplifyStats& s, const Mesh& before, const Mesh& after,
                        const Vec3d& scale);

// The process's peak resident set so far, MB.
double peak_rss_mb();

// Seconds since `t0` on the steady clock, and such a duration as "1.234 s" (the stats' and the
// progress lines' timings).
double seconds_since(std::chrono::steady_clock::time_point t0);
std::string fmt_seconds(double s);

// Worker threads the run may use (TBB's current limit), the stats' "threads".
int stats_threads();

}  // namespace isotile
