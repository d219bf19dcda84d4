// Ear clipping (polygon_triangulation.h).
#include "core/mesh/polygon_triangulation.h"

#include <array>
#include <cmath>

namespace isotile {

namespace {

using Point = std::array<double, 2>;

double cross(const Point& a, const Point& b, const Point& c) {
  return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

// Whether p lies in the closed triangle abc (counter-clockwise): a corner touching an ear's edge
// from outside would be cut off by it.
bool in_triangle(const Point& p, const Point& a, const Point& b, const Point& c) {
  return cross(a, b, p) >= 0 && cross(b, c, p) >= 0 && cross(c, a, p) >= 0;
}

}  // namespace

void triangulate_polygon(const std::vector<Vec3f>& positions, const std::uint32_t* corners,
                         std::size_t n, Tri* out) {
  // The plane: Newell's normal, whose largest component names the axis the polygon is seen
  // along; its sign turns the projection so that the polygon runs counter-clockwise.
  double normal[3] = {0, 0, 0};
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& p = positions[corners[i]];
    const Vec3f& q = positions[corners[(i + 1) % n]];
    for (int a = 0; a < 3; ++a) {
      const int b = (a + 1) % 3, c = (a + 2) % 3;
      normal[a] += (double(p[b]) - double(q[b])) * (double(p[c]) + double(q[c]));
    }
  }
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (std::fabs(normal[a]) > std::fabs(normal[axis])) axis = a;
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const double flip = normal[axis] < 0 ? -1.0 : 1.0;
  std::vector<Point> point(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3f& p = positions[corners[i]];
    point[i] = {double(p[u]), flip * double(p[v])};
  }

  std::size_t written = 0;
  const auto emit = [&](std::size_t a, std::size_t b, std::size_t c) {
    out[written++] = {corners[a], corners[b], corners[c]};
  };
  // The corners not yet cut off, as a ring.
  std::vector<std::size_t> next(n), prev(n);
  for (std::size_t i = 0; i < n; ++i) {
    next[i] = (i + 1) % n;
    prev[i] = (i + n - 1) % n;
  }
  const auto turns_left = [&](std::size_t b) {
    return cross(point[prev[b]], point[b], point[next[b]]) > 0;
  };
  bool convex = true;
  for (std::size_t b = 0; b < n && convex; ++b) convex = turns_left(b);
  // No area (or no plane) leaves nothing to clip by, and a convex polygon needs no clipping: the
  // fan from the first corner.
  std::size_t first = 0, left = n;
  if (!convex && normal[axis] != 0 && std::isfinite(normal[axis])) {
    // An ear: a corner that turns left and whose triangle with its neighbours holds no other
    // corner (one at the position of one of its own, where the polygon touches itself, does not
    // count). Only the cut corner's neighbours change, so only they are looked at again: O(n^2).
    const auto is_ear = [&](std::size_t b) {
      if (!turns_left(b)) return false;
      const Point &pa = point[prev[b]], &pb = point[b], &pc = point[next[b]];
      for (std::size_t j = next[next[b]]; j != prev[b]; j = next[j])
        if (point[j] != pa && point[j] != pb && point[j] != pc && in_triangle(point[j], pa, pb, pc))
          return false;
      return true;
    };
    std::vector<char> ear(n);
    for (std::size_t b = 0; b < n; ++b) ear[b] = is_ear(b);
    std::size_t at = 1, looked = 0;
    while (left > 3 && looked < left) {
      if (!ear[at]) {
        at = next[at];
        ++looked;
        continue;
      }
      const std::size_t a = prev[at], c = next[at];
      emit(a, at, c);
      next[a] = c;
      prev[c] = a;
      if (at == first) first = c;
      --left;
      ear[a] = is_ear(a);
      ear[c] = is_ear(c);
      at = c;
      looked = 0;
    }
  }
  for (std::size_t b = next[first]; next[b] != first; b = next[b]) emit(first, b, next[b]);
}

}  // namespace isotile
