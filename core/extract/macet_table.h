// The triangulation table Macet emits: Teem's Macet-derived table where it is safe, Marching
// Cubes' table elsewhere. Internal to core/.
//
// Teem (<teem/seek.h>, seekContour3DTopoHackTriangle / seekContour3DTopoHackEdge) ships a case
// table generated from the one distributed with Macet. It has MC's topology but triangulates many
// polygons differently: it avoids most triangles whose three crossings lie on edges of three
// different axes forming a path, the group where MC's worst triangles sit (see
// docs/macet.md). Teem numbers cube edges its own way; this adapter maps them to MC's numbering
// and accepts a case only when, after the mapping,
//   * its crossed edges equal MC's,
//   * its triangles bound exactly MC's polygons (so the surface, and how it meets the
//     neighbouring cells, is MC's), with the same orientation or the exact reverse (then flipped),
//   * no diagonal joins two crossings of one cube face (the neighbour could draw it too and make a
//     non-manifold edge; MC's table obeys the same rule).
// Any other case keeps MC's triangulation. The result is built once, on first use.
#pragma once

#include <array>
#include <cstdint>

#include "core/extract/marching_cubes_tables.h"

namespace isotile::detail {

struct MacetCaseTable {
  std::array<std::uint8_t, 256> triangle_count{};
  std::array<std::uint16_t, 256> edge_mask{};  // MC's edge numbering
  std::array<std::array<std::int8_t, 3 * mc::kMaxTrianglesPerCase>, 256> triangles{};
  int from_teem = 0;  // cases taken from Teem's table (flipped or not)
  int flipped = 0;    // of those, cases whose winding had to be reversed
  int different = 0;  // of those, cases triangulated differently from MC
};

// Teem's table adapted as above (use_teem), or MC's own table.
const MacetCaseTable& macet_case_table(bool use_teem = true);

}  // namespace isotile::detail
