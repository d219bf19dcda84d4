// The table of table-driven Dual Contouring (paper Sec. III-B, Figure 3), shared by every
// extraction path (the CPU extractor reads it directly; GL paths upload the same arrays).
//
// Conventions
//   A sample s = (i, j, k) owns the three grid edges leaving it along +x, +y and +z. Its case code
//   has bit 3 set when s is inside (value >= iso) and bit a (a = 0, 1, 2 for x, y, z) set when the
//   far end of its +a edge is inside. Edge a is crossed when bit a differs from bit 3.
//   A crossed edge gets one quad joining the dual vertices of the four cells that share it; those
//   cells lie in the 2x2x2 block of cells around s, which the paper labels V'0..V'7.
//   kBlockCell[n] is the offset of the cell of V'n from s: cell (i + dx, j + dy, k + dz), where
//   cell (i, j, k) is the cube with lower corner at sample (i, j, k). V'0..V'3 are the cells with
//   dz = 0 going round s (s's own cell, then -y, -x-y, -x), V'4..V'7 the same with dz = -1. The
//   paper's text places V'1 and V'4 "upwards" in y and z; only with up read as -1 do its three
//   quads surround edges that leave s, as its table requires.
//
// What differs from Figure 3 as printed, and why
//   - Rows 0100 and 1011 print (V'4, V'0, V'3, V'2) for the z-edge. Those four cells do not share
//     a common edge; every other row uses (V'0, V'3, V'2, V'1), which does. Corrected here.
//   - The figure gives complementary codes the same vertex order. As printed, each quad faces +a
//     (right-hand rule over the cell centres), which is outward when s is inside and its +a
//     neighbour outside. When s is outside the quad must face -a, so rows with bit 3 clear list
//     the printed quads reversed. Normals then always point from inside to outside (see mesh.h).
#pragma once

#include <array>
#include <cstdint>

#include "core/extract/marching_cubes_tables.h"

namespace isotile::dc {

inline constexpr std::array<std::array<std::int8_t, 3>, 8> kBlockCell = {{
    {0, 0, 0},     // V'0: s's own cell
    {0, -1, 0},    // V'1
    {-1, -1, 0},   // V'2
    {-1, 0, 0},    // V'3
    {0, 0, -1},    // V'4
    {0, -1, -1},   // V'5
    {-1, -1, -1},  // V'6
    {-1, 0, -1},   // V'7
}};

struct DcCase {
  std::uint8_t count;                                // quads to emit, one per crossed edge
  std::array<std::uint8_t, 3> axis;                  // the edge of each quad (0 x, 1 y, 2 z)
  std::array<std::array<std::uint8_t, 4>, 3> quads;  // V' labels, wound outward
};

// Printed quads X = (4,0,1,5), Y = (4,7,3,0), Z = (0,3,2,1) for s inside; reversed for s outside.
inline constexpr std::array<DcCase, 16> kDcTable = {{
    /* 0000 */ {0, {}, {}},
    /* 0001 */ {1, {0}, {{{5, 1, 0, 4}}}},
    /* 0010 */ {1, {1}, {{{0, 3, 7, 4}}}},
    /* 0011 */ {2, {0, 1}, {{{5, 1, 0, 4}, {0, 3, 7, 4}}}},
    /* 0100 */ {1, {2}, {{{1, 2, 3, 0}}}},
    /* 0101 */ {2, {0, 2}, {{{5, 1, 0, 4}, {1, 2, 3, 0}}}},
    /* 0110 */ {2, {1, 2}, {{{0, 3, 7, 4}, {1, 2, 3, 0}}}},
    /* 0111 */ {3, {0, 1, 2}, {{{5, 1, 0, 4}, {0, 3, 7, 4}, {1, 2, 3, 0}}}},
    /* 1000 */ {3, {0, 1, 2}, {{{4, 0, 1, 5}, {4, 7, 3, 0}, {0, 3, 2, 1}}}},
    /* 1001 */ {2, {1, 2}, {{{4, 7, 3, 0}, {0, 3, 2, 1}}}},
    /* 1010 */ {2, {0, 2}, {{{4, 0, 1, 5}, {0, 3, 2, 1}}}},
    /* 1011 */ {1, {2}, {{{0, 3, 2, 1}}}},
    /* 1100 */ {2, {0, 1}, {{{4, 0, 1, 5}, {4, 7, 3, 0}}}},
    /* 1101 */ {1, {1}, {{{4, 7, 3, 0}}}},
    /* 1110 */ {1, {0}, {{{4, 0, 1, 5}}}},
    /* 1111 */ {0, {}, {}},
}};

// Surface patches of a cell, for DcVertices::Patch (manifold Dual Contouring, as in Dual Marching
// Cubes): the polygons Marching Cubes' table draws in a cell of each case, found as the connected
// components of its triangles (triangles of one polygon share edges; polygons share none). A
// crossed cell edge belongs to exactly one patch; patches are numbered by their lowest edge, so
// the numbering is a function of the case alone and every path derives the same one. The MC rule
// on ambiguous faces depends on the face's samples only, so the two cells sharing a face agree on
// which crossings of that face are joined.
struct PatchTable {
  std::array<std::uint8_t, 256> count{};                  // patches of the case (0 to 4)
  std::array<std::array<std::int8_t, 12>, 256> patch{};   // patch of each edge; -1: not crossed
  std::array<std::array<std::uint16_t, 4>, 256> edges{};  // edge mask of each patch
};

inline constexpr PatchTable kPatchTable = [] {
  PatchTable t{};
  for (int cs = 0; cs < 256; ++cs) {
    std::array<int, 12> root{};
    for (int e = 0; e < 12; ++e) root[e] = e;
    auto find = [&root](int e) {
      while (root[e] != e) e = root[e];
      return e;
    };
    const auto& tri = mc::kCaseTable.triangles[cs];
    for (int f = 0; f < mc::kCaseTable.triangle_count[cs]; ++f)
      for (int v = 1; v < 3; ++v) {
        const int a = find(tri[3 * f]), b = find(tri[3 * f + v]);
        if (a != b) root[a < b ? b : a] = a < b ? a : b;  // the lower edge stays the root
      }
    std::array<int, 12> number{};
    for (int& n : number) n = -1;
    int count = 0;
    for (int e = 0; e < 12; ++e) {
      t.patch[cs][e] = -1;
      if (!((mc::kCaseTable.edge_mask[cs] >> e) & 1)) continue;
      const int r = find(e);
      if (number[r] < 0) number[r] = count++;
      t.patch[cs][e] = static_cast<std::int8_t>(number[r]);
      t.edges[cs][number[r]] |= static_cast<std::uint16_t>(1u << e);
    }
    t.count[cs] = static_cast<std::uint8_t>(count);
  }
  return t;
}();

// The cell edge (MC numbering) that grid edge (s, axis) is in the cell of V'n (kBlockCell[n]):
// the edge along `axis` whose lower corner sits at s minus the cell's corner.
inline constexpr std::array<std::array<std::int8_t, 3>, 8> kBlockEdge = [] {
  std::array<std::array<std::int8_t, 3>, 8> out{};
  for (int n = 0; n < 8; ++n)
    for (int axis = 0; axis < 3; ++axis) {
      int corner = 0;
      for (int a = 0; a < 3; ++a) corner |= (-kBlockCell[n][a]) << a;
      out[n][axis] = -1;
      for (int e = 4 * axis; e < 4 * axis + 4; ++e)
        if (mc::kEdgeCorners[e][0] == corner) out[n][axis] = static_cast<std::int8_t>(e);
    }
  return out;
}();

}  // namespace isotile::dc
