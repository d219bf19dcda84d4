// Per-vertex value ranges of the cells around a vertex: scikit-image's `values` output.
//
// scikit-image's marching_cubes (0.19) reports for each vertex the largest (max - min) of the
// eight samples of the cells whose faces use it, "a measure for the maximum value of the data in
// the local region near each vertex" for colour maps. isotile computes the same from the mesh and
// the samples, for any method: the cells a vertex lies in (the four around an edge for Marching
// Cubes, one for a vertex inside a cell, up to eight for one on a grid point).
#pragma once

#include <vector>

#include "core/mesh/mesh.h"
#include "core/volume/volume.h"

namespace isotile {

// One value per position of `mesh`, whose positions are in the grid frame of `view` (origin +
// spacing x global index). Positions outside the view take the nearest cell's range.
// Deterministic for any thread count.
// With `mask` (UInt8, the dims of `view`; core/extract/cell_mask.h), only the cells inside it
// (all eight corners set) count: the cells whose faces were kept, as scikit-image skips the
// others.
std::vector<float> vertex_cell_ranges(const VolumeView& view, const Mesh& mesh,
                                      const VolumeView* mask = nullptr);

}  // namespace isotile
