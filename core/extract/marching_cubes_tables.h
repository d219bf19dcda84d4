// Marching Cubes case tables, generated at compile time and shared by every extraction path (the
// CPU extractor uses them directly; the GL paths upload the same arrays).
//
// Conventions
//   corner c of a cell sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1);
//   case bit c is set when corner c is inside (sample >= iso);
//   edge e runs along axis e / 4 from corner kEdgeCorners[e][0] to kEdgeCorners[e][1] (the +axis
//   end); its other two coordinates are the bits of e % 4 (lower axis first).
//
// How the table is built: on each cube face the crossings are joined by segments that keep the
// inside on the same side; on a face whose inside corners lie diagonally (an ambiguous face) the
// segments separate the two inside corners. The rule depends only on the face's four samples, so
// the two cells sharing a face always agree and the mesh has no cracks. Segments chain into closed
// polygons, each split into triangles by ear clipping that never draws a diagonal between two
// crossings on one face (the neighbour could draw it too, making a non-manifold edge). Winding:
// normals point out of the inside (see mesh.h). With this rule the tables give the same triangle
// count as VTK's vtkMarchingCubes / vtkFlyingEdges3D on the paper's volumes (checked in the
// benchmark).
#pragma once

#include <array>
#include <cstdint>

namespace isotile::mc {

inline constexpr int kMaxTrianglesPerCase = 5;

inline constexpr std::array<std::array<std::uint8_t, 2>, 12> kEdgeCorners = [] {
  std::array<std::array<std::uint8_t, 2>, 12> e{};
  for (int edge = 0; edge < 12; ++edge) {
    const int axis = edge / 4, m = edge % 4;
    const int u = axis == 0 ? 1 : 0;  // lower of the two other axes
    const int v = axis == 2 ? 1 : 2;  // higher of the two other axes
    const int lo = ((m & 1) << u) | (((m >> 1) & 1) << v);
    e[edge] = {static_cast<std::uint8_t>(lo), static_cast<std::uint8_t>(lo | (1 << axis))};
  }
  return e;
}();

// Where the vertex of cell edge e lives, seen from cell row (j, k): the point row that owns it
// (0 = (j,k), 1 = (j+1,k), 2 = (j,k+1), 3 = (j+1,k+1)), the edge's axis, and the x offset of its
// owning point from the cell.
struct EdgeHome {
  std::uint8_t row, axis, dx;
};
inline constexpr std::array<EdgeHome, 12> kEdgeHome = [] {
  std::array<EdgeHome, 12> h{};
  for (int e = 0; e < 12; ++e) {
    const int lo = kEdgeCorners[e][0];  // corner x + 2y + 4z of the owning point
    h[e] = {static_cast<std::uint8_t>(((lo >> 1) & 1) | (((lo >> 2) & 1) << 1)),
            static_cast<std::uint8_t>(e / 4), static_cast<std::uint8_t>(lo & 1)};
  }
  return h;
}();

struct CaseTable {
  std::array<std::uint8_t, 256> triangle_count{};
  std::array<std::uint16_t, 256> edge_mask{};  // bit e set when edge e is crossed
  // Triangles as triples of edge indices, kMaxTrianglesPerCase * 3 entries per case, -1 padded.
  std::array<std::array<std::int8_t, 3 * kMaxTrianglesPerCase>, 256> triangles{};
};

namespace detail {

constexpr int edge_between(int a, int b) {
  for (int e = 0; e < 12; ++e)
    if ((kEdgeCorners[e][0] == a && kEdgeCorners[e][1] == b) ||
        (kEdgeCorners[e][0] == b && kEdgeCorners[e][1] == a))
      return e;
  return -1;
}

// True when cube edges e1 and e2 lie on a common face.
constexpr bool share_face(int e1, int e2) {
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      bool on = true;
      for (int e : {e1, e2})
        for (int c : kEdgeCorners[e]) on = on && ((c >> axis) & 1) == side;
      if (on) return true;
    }
  return false;
}

// Triangulates the polygon of crossings poly[0..len) by clipping ears, appending edge triples to
// out. A diagonal between two crossings on one cube face is refused: the cell across that face
// could draw the same diagonal, and the edge would then have four triangles. Backtracks until
// every diagonal is allowed; returns false when no such triangulation exists.
constexpr bool triangulate(const std::array<int, 12>& poly, int len,
                           std::array<std::int8_t, 3 * kMaxTrianglesPerCase>& out, int& n) {
  if (len == 3) {
    if (n >= kMaxTrianglesPerCase) return false;
    for (int v = 0; v < 3; ++v) out[3 * n + v] = static_cast<std::int8_t>(poly[v]);
    ++n;
    return true;
  }
  for (int i = 0; i < len; ++i) {
    const int prev = poly[(i + len - 1) % len], cur = poly[i], next = poly[(i + 1) % len];
    if (share_face(prev, next) || n >= kMaxTrianglesPerCase) continue;
    std::array<int, 12> rest{};
    for (int k = 0, r = 0; k < len; ++k)
      if (k != i) rest[r++] = poly[k];
    const int saved = n;
    out[3 * n + 0] = static_cast<std::int8_t>(prev);
    out[3 * n + 1] = static_cast<std::int8_t>(cur);
    out[3 * n + 2] = static_cast<std::int8_t>(next);
    ++n;
    if (triangulate(rest, len - 1, out, n)) return true;
    n = saved;
  }
  return false;
}

constexpr CaseTable build_case_table() {
  CaseTable t{};
  for (int c = 0; c < 256; ++c) {
    auto inside = [c](int corner) { return (c >> corner) & 1; };
    // next[e]: the crossing that follows e on the polygon through it.
    std::array<int, 12> next{};
    for (int& n : next) n = -1;
    for (int axis = 0; axis < 3; ++axis) {
      // (u, v, axis) right-handed, so (0,0),(1,0),(1,1),(0,1) in (u, v) is counter-clockwise
      // seen from the +axis side.
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int side = 0; side < 2; ++side) {
        std::array<int, 4> corner{};
        const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
        for (int i = 0; i < 4; ++i) {
          const int k = side ? i : (4 - i) % 4;  // reverse the order on the -axis face
          corner[i] = (uv[k][0] << u) | (uv[k][1] << v) | (side << axis);
        }
        // Face edges in counter-clockwise order seen from outside; enter = outside -> inside.
        std::array<int, 4> edge{}, enter{}, active{};
        int n_active = 0;
        for (int i = 0; i < 4; ++i) {
          const int a = corner[i], b = corner[(i + 1) % 4];
          edge[i] = edge_between(a, b);
          active[i] = inside(a) != inside(b);
          enter[i] = !inside(a) && inside(b);
          n_active += active[i];
        }
        // From each entering crossing, the segment runs to the next crossing counter-clockwise,
        // which cuts off the inside run that starts there. On an ambiguous face that run is a
        // single corner, so the two inside corners are separated.
        for (int i = 0; i < 4; ++i) {
          if (!active[i] || !enter[i]) continue;
          int j = (i + 1) % 4;
          while (!active[j]) j = (j + 1) % 4;
          next[edge[i]] = edge[j];
        }
        (void)n_active;
      }
    }
    std::uint16_t mask = 0;
    for (int e = 0; e < 12; ++e)
      if (inside(kEdgeCorners[e][0]) != inside(kEdgeCorners[e][1])) mask |= 1u << e;
    t.edge_mask[c] = mask;
    for (auto& x : t.triangles[c]) x = -1;
    int n_tri = 0;
    std::uint16_t seen = 0;
    for (int start = 0; start < 12; ++start) {
      if (!((mask >> start) & 1) || ((seen >> start) & 1)) continue;
      std::array<int, 12> poly{};
      int len = 0;
      for (int e = start; !((seen >> e) & 1); e = next[e]) {
        seen |= 1u << e;
        poly[len++] = e;
      }
      if (!triangulate(poly, len, t.triangles[c], n_tri)) throw "no valid triangulation";
    }
    t.triangle_count[c] = static_cast<std::uint8_t>(n_tri);
  }
  return t;
}

}  // namespace detail

inline constexpr CaseTable kCaseTable = detail::build_case_table();

}  // namespace isotile::mc
