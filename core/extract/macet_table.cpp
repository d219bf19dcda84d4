#include "core/extract/macet_table.h"

#include <teem/seek.h>

#include <algorithm>
#include <utility>
#include <vector>

namespace isotile::detail {

namespace {

// Teem's cube edges as corner pairs (corner index x + 2y + 4z, as in MC), from Teem's extract.c.
constexpr int kTeemEdgeCorners[12][2] = {{0, 1}, {0, 2}, {1, 3}, {2, 3}, {0, 4}, {1, 5},
                                         {2, 6}, {3, 7}, {4, 5}, {4, 6}, {5, 7}, {6, 7}};

using Tris = std::vector<std::array<int, 3>>;
using Directed = std::vector<std::pair<int, int>>;

// Directed triangle sides split into those joining two crossings of one cube face and the others.
void sides(const Tris& tris, Directed& on_face, Directed& inner) {
  on_face.clear();
  inner.clear();
  for (const auto& t : tris)
    for (int s = 0; s < 3; ++s) {
      const int a = t[s], b = t[(s + 1) % 3];
      (mc::detail::share_face(a, b) ? on_face : inner).push_back({a, b});
    }
  std::sort(on_face.begin(), on_face.end());
  std::sort(inner.begin(), inner.end());
}

// Every inner side is used once in each direction (the triangles form one consistent patch).
bool inner_paired(const Directed& inner) {
  for (const auto& [a, b] : inner)
    if (std::count(inner.begin(), inner.end(), std::pair{a, b}) != 1 ||
        std::count(inner.begin(), inner.end(), std::pair{b, a}) != 1)
      return false;
  return true;
}

MacetCaseTable build(bool use_teem) {
  MacetCaseTable t;
  int teem_to_mc[12];
  for (int e = 0; e < 12; ++e)
    teem_to_mc[e] = mc::detail::edge_between(kTeemEdgeCorners[e][0], kTeemEdgeCorners[e][1]);
  for (int c = 0; c < 256; ++c) {
    const auto& mct = mc::kCaseTable;
    t.edge_mask[c] = mct.edge_mask[c];
    t.triangle_count[c] = mct.triangle_count[c];
    t.triangles[c] = mct.triangles[c];
    if (!use_teem) continue;

    Tris mc_tris, teem_tris;
    for (int i = 0; i < mct.triangle_count[c]; ++i)
      mc_tris.push_back(
          {mct.triangles[c][3 * i], mct.triangles[c][3 * i + 1], mct.triangles[c][3 * i + 2]});
    std::uint16_t teem_mask = 0;
    for (int e = 0; e < 12; ++e)
      if ((seekContour3DTopoHackEdge[c] >> e) & 1) teem_mask |= std::uint16_t(1u << teem_to_mc[e]);
    bool ok = teem_mask == mct.edge_mask[c];
    for (int i = 0; ok && i < 16 && seekContour3DTopoHackTriangle[c][i] != -1; i += 3) {
      std::array<int, 3> tri{};
      for (int v = 0; v < 3; ++v) {
        const int e = i + v < 16 ? seekContour3DTopoHackTriangle[c][i + v] : -1;
        if (e < 0 || e >= 12) {
          ok = false;
          break;
        }
        tri[v] = teem_to_mc[e];
      }
      teem_tris.push_back(tri);
    }
    ok = ok && teem_tris.size() == mc_tris.size();
    if (!ok) continue;

    Directed mc_face, mc_inner, face, inner;
    sides(mc_tris, mc_face, mc_inner);
    sides(teem_tris, face, inner);
    bool flip = false;
    if (face != mc_face) {
      for (auto& tri : teem_tris) std::swap(tri[1], tri[2]);
      sides(teem_tris, face, inner);
      flip = true;
    }
    if (face != mc_face || !inner_paired(inner)) continue;
    for (std::size_t i = 0; i < teem_tris.size(); ++i)
      for (int v = 0; v < 3; ++v)
        t.triangles[c][3 * i + v] = static_cast<std::int8_t>(teem_tris[i][v]);
    ++t.from_teem;
    t.flipped += flip;
    t.different += teem_tris != mc_tris;
  }
  return t;
}

}  // namespace

const MacetCaseTable& macet_case_table(bool use_teem) {
  static const MacetCaseTable teem = build(true);
  static const MacetCaseTable plain = build(false);
  return use_teem ? teem : plain;
}

}  // namespace isotile::detail
