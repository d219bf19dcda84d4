// The surface patches of a cell for manifold Dual Contouring (DcVertices::Patch), with the one
// repair Marching Cubes' table needs for them.
//
// A cell's patches are the polygons Marching Cubes draws in it (kPatchTable). Their dual mesh
// (one vertex per polygon, one quad per crossed edge) is manifold except where two cells sharing
// an ambiguous face (crossings on all four of its edges) each join that face's two segments into
// one polygon: the inside then wraps round an outside channel through the face, the two polygons
// meet along both segments, and the dual edge between their vertices gets four quads (bonsai at
// 49.5: 137 such faces). There the face is resolved the other way in both cells (its segments
// cut off the outside corners instead of the inside ones), which closes the channel: each polygon
// splits in two along the face, every dual edge has two quads again, and no face is added or
// removed. The decision reads the cases of the two cells only, so every cell, brick and path
// takes it alike.
#pragma once

#include <array>
#include <cstdint>

#include "core/extract/dual_contouring_table.h"

namespace isotile::dc {

// Face f of a cell: axis f / 2, side f % 2 (1: the +axis face, shared with the cell at +axis).
// kConflictFaces[cs] has bit f set when face f of a cell of case cs is ambiguous and its four
// crossings lie in one patch; a face flips when the cells on both sides have its bit.
extern const std::array<std::uint8_t, 256> kConflictFaces;

// The patches of a cell of case `cs` whose faces in the mask `flips` are resolved the other way
// and whose faces in `open` lie on the volume border. Segments on a border face are left out:
// the crossings of border edges get no quad, so a polygon that reaches the border in two places
// (a cell on an edge of the volume) would otherwise pinch its vertex into two fans; cut there, it
// becomes one patch per stretch between border faces.
// At most kMaxPatches, whatever the flips and border faces (a test enumerates them all): vertex
// keys leave room for four per cell.
inline constexpr int kMaxPatches = 4;
struct CellPatches {
  int count = 0;
  std::array<std::int8_t, 12> patch{};             // of each edge; -1: not crossed
  std::array<std::uint16_t, kMaxPatches> edges{};  // edge mask of each patch (by lowest edge)
};
CellPatches cell_patches(int cs, unsigned flips, unsigned open);

// The cube edges on the faces in `open` (a mask of 12 edges), and the crossed edges of a cell of
// case `cs` off them: those that can get a quad. A cell whose crossed edges all lie on the
// volume's border (no live edge) gets no vertex in either DcVertices mode, as no quad would use
// it; cell_patches() then has no patch.
unsigned border_edges(unsigned open);
unsigned live_edges(int cs, unsigned open);
// Whether a mixed cell of case `cs` with border faces `open` gets a vertex at all.
inline bool has_vertex(int cs, unsigned open) {
  return open == 0 || live_edges(cs, open) != 0;
}

// The same, from the table where nothing flips and no face is on the border (almost every cell).
inline CellPatches cell_patches_or_table(int cs, unsigned flips, unsigned open) {
  if (flips || open) return cell_patches(cs, flips, open);
  CellPatches out;
  out.count = kPatchTable.count[cs];
  out.patch = kPatchTable.patch[cs];
  out.edges = kPatchTable.edges[cs];
  return out;
}

// The faces of a cell of case `cs` to flip, given the cases of its six face neighbours
// (`neighbour(f)`: the case of the cell across face f, or -1 where there is none).
template <class Neighbour>
unsigned face_flips(int cs, Neighbour&& neighbour) {
  unsigned flips = 0;
  for (unsigned m = kConflictFaces[cs]; m; m &= m - 1) {
    const int f = __builtin_ctz(m);
    const int other = neighbour(f);
    if (other >= 0 && ((kConflictFaces[other] >> (f ^ 1)) & 1)) flips |= 1u << f;
  }
  return flips;
}

// The faces of cell `cell` (global index) on the border of a volume of `dims` samples.
template <class Cell, class Dims>
unsigned border_faces(const Cell& cell, const Dims& dims) {
  unsigned out = 0;
  for (int a = 0; a < 3; ++a) {
    if (cell[a] == 0) out |= 1u << (2 * a);
    if (cell[a] + 2 == dims[a]) out |= 1u << (2 * a + 1);
  }
  return out;
}

// Offsets of the cell across face f.
inline constexpr std::array<std::array<std::int8_t, 3>, 6> kFaceNeighbour = {
    {{-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 1}}};

}  // namespace isotile::dc
