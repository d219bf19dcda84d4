// Marching Cubes on the CPU: the reference extractor.
//
// Classification: a sample is inside when value >= iso (the same test everywhere, so cells that
// share a face or an edge always agree and the mesh has no cracks). Every crossed grid edge gets
// exactly one vertex, interpolated from its lower-index end to its upper-index end whichever cell
// asks, at world position origin + spacing * (global index + t).
//
// Parallel and deterministic: count, exclusive scan, fill over rows of the grid. Vertices come in
// ascending key order: the edge from global sample s to s + e_a has key lin(s) * 3 + a, with
// lin(s) = s.x + N.x * (s.y + N.y * s.z) over the global dims N, i.e. by z, y, x, then axis.
// Triangles come cell by cell in the same z, y, x order and, within a cell, in case table order.
// The output is byte-identical for any thread count, and (see `cells`) the order does not depend
// on how a volume is cut into bricks.
#pragma once

#include <cstdint>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/volume/volume.h"

namespace isotile {

struct MarchingCubesOptions {
  double iso = 0.0;
  bool normals = false;  // unit normals from central-difference gradients, pointing outward
  // Brick mode, in global cell indices; empty: every cell of the view. The view must then cover
  // these cells grown by marching_cubes_halo() samples on every side (less at the volume border).
  // Output: the triangles of these cells, and the vertices of every crossed edge owned by a sample
  // of the closed box [cells.lo, cells.hi] (so a brick's list includes the vertices on its upper
  // faces, which its neighbours own). Gradients are one-sided only at the volume border, so a
  // vertex shared by two bricks is bit-identical in both.
  Box3 cells{};
  // Told of the work's progress (Stage::Count, then Stage::Extract; core/progress.h), a z-slice of
  // rows at a time; null: nobody listens. Cancelling throws Cancelled.
  Progress* progress = nullptr;
};

// Samples beyond the cells that brick mode reads: 1 for positions, 2 with normals.
int marching_cubes_halo(const MarchingCubesOptions& options);

// Extracts the isosurface of the cells of `view`. Throws CapacityError when the mesh would need
// more than 2^32 - 1 vertices.
Mesh marching_cubes(const VolumeView& view, const MarchingCubesOptions& options);

// The keys of the vertices marching_cubes(view, options) returns, in the same order, without
// placing them. Macet crosses the same edges, so its vertices have these keys too.
std::vector<std::uint64_t> marching_cubes_vertex_keys(const VolumeView& view,
                                                      const MarchingCubesOptions& options);

}  // namespace isotile
