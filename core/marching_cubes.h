// Marching Cubes on the CPU: the reference extractor.
//
// Classification: a sample is inside when value >= iso (the same test everywhere, so cells that
// share a face or an edge always agree and the mesh has no cracks). Every crossed grid edge gets
// exactly one vertex, interpolated from its lower-index end to its upper-index end whichever cell
// asks, at world position origin + spacing * (global index + t).
//
// Parallel and deterministic: count, exclusive scan, fill over rows of the grid. Vertices are
// numbered row by row (rows ordered by z, then y), within a row x-edges, then y-edges, then
// z-edges, each by x; triangles cell by cell in the same row order and, within a cell, in case
// table order. The output is byte-identical for any thread count.
#pragma once

#include "core/mesh.h"
#include "core/volume.h"

namespace isotile {

struct MarchingCubesOptions {
  double iso = 0.0;
  bool normals = false;  // unit normals from central-difference gradients, pointing outward
};

// Extracts the isosurface of the cells of `view`. Throws CapacityError when the mesh would need
// more than 2^32 - 1 vertices.
Mesh marching_cubes(const VolumeView& view, const MarchingCubesOptions& options);

}  // namespace isotile
