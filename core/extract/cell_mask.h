// Keeping only the faces of cells inside a mask (scikit-image's `mask` argument).
//
// A face belongs to the cell that holds its centroid (the cell it was made in, for Marching
// Cubes and Macet; for Dual Contouring, whose faces join the vertices of four cells, the cell
// nearest their middle). A cell is inside the mask when all eight of its corner samples are set.
#pragma once

#include "core/mesh/mesh.h"
#include "core/volume/volume.h"

namespace isotile {

// The faces of `mesh` (positions in the grid frame of `view`) whose cell is inside `mask`, a
// UInt8 view with the dims of `view` (non-zero: set), and the vertices they use, in their
// original order (normals kept alongside). Throws InputError when the mask's type or dims do not
// match.
Mesh keep_masked_cells(const Mesh& mesh, const VolumeView& view, const VolumeView& mask);

}  // namespace isotile
