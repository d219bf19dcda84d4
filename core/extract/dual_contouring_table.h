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

}  // namespace isotile::dc
