#include "core/mesh/surface_distance.h"

#include <CGAL/AABB_segment_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/errors.h"

namespace isotile {

namespace {

using K = CGAL::Simple_cartesian<double>;
using Point = K::Point_3;
using Triangle = K::Triangle_3;
using Segment = K::Segment_3;
using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<Triangle>::const_iterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
using SegmentPrimitive = CGAL::AABB_segment_primitive<K, std::vector<Segment>::const_iterator>;
using SegmentTree = CGAL::AABB_tree<CGAL::AABB_traits<K, SegmentPrimitive>>;

// Fixed chunks make the sums independent of the thread count.
constexpr std::size_t kChunk = 1 << 12;

Point scaled(const Vec3f& p, const Vec3d& s) {
  return {double{p[0]} * s[0], double{p[1]} * s[1], double{p[2]} * s[2]};
}

// A mesh's faces, scaled: those with an area as triangles (quads as two); those of none, whose
// corners lie on a line, as that line's longest segment (Marching Cubes makes such faces where
// samples equal the isovalue: they lie on the surface, and CGAL's closest point on a triangle
// divides by its area); the vertices of both are `used`. A face whose corners meet at one point
// is neither. With the faces of no area left out of both sides, their corners were measured to
// the nearest face with one: bonsai's MC mesh at 50 was 30.08 voxels from itself.
struct Surface {
  std::vector<Triangle> triangles;
  std::vector<Segment> segments;
  std::vector<char> used;
};
Surface scaled_surface(const Mesh& mesh, const Vec3d& s) {
  check_face_indices(mesh);
  Surface out;
  out.triangles.reserve(mesh.triangles.size() + 2 * mesh.quads.size());
  out.used.assign(mesh.positions.size(), 0);
  auto add = [&](std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    const Triangle t(scaled(mesh.positions[a], s), scaled(mesh.positions[b], s),
                     scaled(mesh.positions[c], s));
    if (!t.is_degenerate()) {
      out.triangles.push_back(t);
    } else {
      int longest = 0;
      for (int i = 1; i < 3; ++i)
        if (CGAL::squared_distance(t[i], t[(i + 1) % 3]) >
            CGAL::squared_distance(t[longest], t[(longest + 1) % 3]))
          longest = i;
      if (t[longest] == t[(longest + 1) % 3]) return;
      out.segments.emplace_back(t[longest], t[(longest + 1) % 3]);
    }
    out.used[a] = out.used[b] = out.used[c] = 1;
  };
  for (const Tri& t : mesh.triangles) add(t[0], t[1], t[2]);
  for (const Quad& q : mesh.quads) {
    add(q[0], q[1], q[2]);
    add(q[0], q[2], q[3]);
  }
  return out;
}

// The closest points of a surface, trees built before the parallel queries: CGAL builds them
// lazily on first use otherwise, which is not thread-safe.
class Closest {
 public:
  explicit Closest(const Surface& s)
      : triangles_(s.triangles.begin(), s.triangles.end()),
        segments_(s.segments.begin(), s.segments.end()),
        any_segment_(!s.segments.empty()) {
    triangles_.build();
    triangles_.accelerate_distance_queries();
    if (any_segment_) {
      segments_.build();
      segments_.accelerate_distance_queries();
    }
  }
  double squared_distance(const Point& p) const {
    const double d = triangles_.squared_distance(p);
    return any_segment_ ? std::min(d, segments_.squared_distance(p)) : d;
  }

 private:
  Tree triangles_;
  SegmentTree segments_;
  bool any_segment_;
};

// The vertices the surface uses, then `count` points spread over its triangles by area.
std::vector<Point> samples(const Mesh& mesh, const Surface& surface, std::uint64_t count,
                           const Vec3d& s) {
  const std::vector<char>& used = surface.used;
  const std::vector<Triangle>& tris = surface.triangles;
  std::vector<Point> out;
  out.reserve(mesh.positions.size() + count);
  for (std::size_t v = 0; v < used.size(); ++v)
    if (used[v]) out.push_back(scaled(mesh.positions[v], s));

  std::vector<double> cumulative(tris.size());
  double total = 0;
  for (std::size_t i = 0; i < tris.size(); ++i)
    cumulative[i] = total += std::sqrt(tris[i].squared_area());
  if (total <= 0 || count == 0) return out;
  // R2 low-discrepancy sequence (Roberts) for the spot inside each triangle.
  constexpr double kA1 = 0.7548776662466927, kA2 = 0.5698402909980532;
  std::size_t t = 0;
  for (std::uint64_t k = 0; k < count; ++k) {
    const double at = (static_cast<double>(k) + 0.5) * total / static_cast<double>(count);
    while (t + 1 < tris.size() && cumulative[t] < at) ++t;
    const double r1 = std::fmod(0.5 + kA1 * static_cast<double>(k), 1.0);
    const double r2 = std::fmod(0.5 + kA2 * static_cast<double>(k), 1.0);
    const double sr = std::sqrt(r1);
    const double u = 1 - sr, v = sr * (1 - r2), w = sr * r2;
    const Triangle& tri = tris[t];
    out.emplace_back(u * tri[0].x() + v * tri[1].x() + w * tri[2].x(),
                     u * tri[0].y() + v * tri[1].y() + w * tri[2].y(),
                     u * tri[0].z() + v * tri[1].z() + w * tri[2].z());
  }
  return out;
}

OneWayDistance one_way(const std::vector<Point>& from, const Closest& to) {
  const std::size_t n = from.size();
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<double> sum(chunks, 0.0), max(chunks, 0.0);
  std::vector<std::size_t> arg(chunks, 0);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    double s = 0, m = -1;
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const double d = std::sqrt(to.squared_distance(from[i]));
      s += d;
      if (d > m) {
        m = d;
        arg[c] = i;
      }
    }
    sum[c] = s;
    max[c] = m;
  });
  OneWayDistance r;
  r.samples = n;
  double s = 0;
  for (std::size_t c = 0; c < chunks; ++c) {
    s += sum[c];
    if (max[c] > r.max) {
      r.max = max[c];
      const Point& p = from[arg[c]];
      r.max_at = {p.x(), p.y(), p.z()};
    }
  }
  r.mean = n ? s / static_cast<double>(n) : 0.0;
  return r;
}

}  // namespace

std::optional<SurfaceDistance> surface_distance(const Mesh& a, const Mesh& b,
                                                const SurfaceDistanceOptions& options) {
  const Surface sa = scaled_surface(a, options.scale), sb = scaled_surface(b, options.scale);
  if (sa.triangles.empty() || sb.triangles.empty()) return std::nullopt;
  const Closest closest_a(sa), closest_b(sb);
  SurfaceDistance r;
  r.a_to_b = one_way(samples(a, sa, options.face_samples, options.scale), closest_b);
  r.b_to_a = one_way(samples(b, sb, options.face_samples, options.scale), closest_a);
  return r;
}

}  // namespace isotile
