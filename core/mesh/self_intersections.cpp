#include "core/mesh/self_intersections.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "core/errors.h"

namespace isotile {

namespace {

// Exact predicates, inexact constructions: every test below is a predicate, so all are exact.
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using P3 = K::Point_3;

P3 point(const Vec3f& v) {
  return {double{v[0]}, double{v[1]}, double{v[2]}};
}

// Is the ray from v through x inside the closed wedge of triangle (v, c, d) at v? Requires x in
// the triangle's plane, x != v, and (v, c, d) not collinear.
bool in_wedge(const P3& v, const P3& c, const P3& d, const P3& x) {
  return CGAL::coplanar_orientation(v, c, d, x) != CGAL::NEGATIVE &&
         CGAL::coplanar_orientation(v, d, c, x) != CGAL::NEGATIVE;
}

// Triangles (v, a0, a1) and (v, b0, b1) sharing only v. Their intersection is convex and
// contains v; if it holds another point p, follow the segment from v through p to where it leaves
// one triangle: that exit lies on the edge opposite v (so that edge meets the other triangle), or
// on an edge through v (so that edge lies in the other triangle's plane, inside its wedge at v).
bool shared_vertex_intersect(const P3& v, const P3& a0, const P3& a1, const P3& b0, const P3& b1) {
  const K::Triangle_3 ta(v, a0, a1), tb(v, b0, b1);
  if (CGAL::do_intersect(K::Segment_3(a0, a1), tb)) return true;
  if (CGAL::do_intersect(K::Segment_3(b0, b1), ta)) return true;
  for (const P3* x : {&a0, &a1})
    if (CGAL::coplanar(v, b0, b1, *x) && in_wedge(v, b0, b1, *x)) return true;
  for (const P3* x : {&b0, &b1})
    if (CGAL::coplanar(v, a0, a1, *x) && in_wedge(v, a0, a1, *x)) return true;
  return false;
}

struct Box {
  std::array<float, 3> lo, hi;
};

}  // namespace

bool triangle_has_area(const std::array<Vec3f, 3>& t) {
  return !CGAL::collinear(point(t[0]), point(t[1]), point(t[2]));
}

bool triangles_intersect(const std::array<Vec3f, 3>& a, const std::array<std::uint32_t, 3>& ia,
                         const std::array<Vec3f, 3>& b, const std::array<std::uint32_t, 3>& ib) {
  // Which corners are shared: ja[k] = the corner of b equal to corner k of a, or -1.
  int ja[3] = {-1, -1, -1}, shared = 0;
  for (int k = 0; k < 3; ++k)
    for (int l = 0; l < 3; ++l)
      if (ia[k] == ib[l]) {
        ja[k] = l;
        ++shared;
      }
  const P3 pa[3] = {point(a[0]), point(a[1]), point(a[2])};
  const P3 pb[3] = {point(b[0]), point(b[1]), point(b[2])};
  switch (shared) {
    case 0:
      return CGAL::do_intersect(K::Triangle_3(pa[0], pa[1], pa[2]),
                                K::Triangle_3(pb[0], pb[1], pb[2]));
    case 1: {
      const int k = ja[0] >= 0 ? 0 : ja[1] >= 0 ? 1 : 2, l = ja[k];
      return shared_vertex_intersect(pa[k], pa[(k + 1) % 3], pa[(k + 2) % 3], pb[(l + 1) % 3],
                                     pb[(l + 2) % 3]);
    }
    case 2: {
      // The common edge (u, w) and the third corners p (of a) and q (of b).
      const int k = ja[0] < 0 ? 0 : ja[1] < 0 ? 1 : 2;  // a's unshared corner
      int l = 0;
      while (l == ja[0] || l == ja[1] || l == ja[2]) ++l;  // b's unshared corner
      const P3& u = pa[(k + 1) % 3];
      const P3& w = pa[(k + 2) % 3];
      return CGAL::coplanar(u, w, pa[k], pb[l]) &&
             CGAL::coplanar_orientation(u, w, pa[k], pb[l]) == CGAL::POSITIVE;
    }
    default:
      return true;  // the same triangle twice
  }
}

SelfIntersections self_intersections(const Mesh& mesh, const SelfIntersectionOptions& options) {
  check_face_indices(mesh);
  SelfIntersections result;
  const std::size_t n_tri = mesh.triangles.size() + 2 * mesh.quads.size();
  if (n_tri >= std::numeric_limits<std::uint32_t>::max())
    throw CapacityError("self-intersection test: more than 2^32 - 1 triangles");
  const std::size_t n_vert = mesh.positions.size();
  // NaN would break the ordering below and the predicates; meshes read from files may hold them.
  for (std::size_t i = 0; i < n_vert; ++i)
    for (float c : mesh.positions[i])
      if (!std::isfinite(c))
        throw InputError("self-intersection test: vertex " + std::to_string(i) +
                         " has a non-finite coordinate");

  // Vertex identity by position: sort indices by (position, index); the first of each run of
  // equal positions names them all.
  std::vector<std::uint32_t> order(n_vert), id(n_vert);
  std::iota(order.begin(), order.end(), 0u);
  const auto& pos = mesh.positions;
  tbb::parallel_sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
    if (pos[x] != pos[y]) return pos[x] < pos[y];
    return x < y;
  });
  for (std::size_t i = 0; i < n_vert; ++i)
    id[order[i]] = (i > 0 && pos[order[i]] == pos[order[i - 1]]) ? id[order[i - 1]] : order[i];

  auto corners = [&](std::size_t t) -> Tri {
    if (t < mesh.triangles.size()) return mesh.triangles[t];
    const std::size_t q = (t - mesh.triangles.size()) / 2;
    const Quad& quad = mesh.quads[q];
    return (t - mesh.triangles.size()) % 2 == 0 ? Tri{quad[0], quad[1], quad[2]}
                                                : Tri{quad[0], quad[2], quad[3]};
  };

  // Triangles with their welded ids and boxes; zero-area ones are dropped here.
  std::vector<Tri> tri(n_tri);
  std::vector<Box> box(n_tri);
  std::vector<unsigned char> live(n_tri);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_tri), [&](const auto& r) {
    for (std::size_t t = r.begin(); t != r.end(); ++t) {
      const Tri c = corners(t);
      tri[t] = {id[c[0]], id[c[1]], id[c[2]]};
      const Vec3f &p0 = pos[c[0]], &p1 = pos[c[1]], &p2 = pos[c[2]];
      live[t] = tri[t][0] != tri[t][1] && tri[t][1] != tri[t][2] && tri[t][0] != tri[t][2] &&
                !CGAL::collinear(point(p0), point(p1), point(p2));
      for (int a = 0; a < 3; ++a) {
        box[t].lo[a] = std::min({p0[a], p1[a], p2[a]});
        box[t].hi[a] = std::max({p0[a], p1[a], p2[a]});
      }
    }
  });

  // Grid: the domain of the live boxes, cells about 1.5 mean box extents wide (isosurface
  // triangles are about a voxel; a cell then holds a few dozen), at most ~4 cells per triangle.
  struct Extent {
    std::array<double, 3> lo{std::numeric_limits<double>::infinity(),
                             std::numeric_limits<double>::infinity(),
                             std::numeric_limits<double>::infinity()};
    std::array<double, 3> hi{-std::numeric_limits<double>::infinity(),
                             -std::numeric_limits<double>::infinity(),
                             -std::numeric_limits<double>::infinity()};
    double size = 0;
    std::uint64_t live = 0;
  };
  constexpr std::size_t kChunk = 8192;
  const std::size_t chunks = (n_tri + kChunk - 1) / kChunk;
  std::vector<Extent> part(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    Extent& e = part[c];
    for (std::size_t t = c * kChunk; t < std::min(n_tri, (c + 1) * kChunk); ++t) {
      if (!live[t]) continue;
      double ext = 0;
      for (int a = 0; a < 3; ++a) {
        e.lo[a] = std::min<double>(e.lo[a], box[t].lo[a]);
        e.hi[a] = std::max<double>(e.hi[a], box[t].hi[a]);
        ext = std::max<double>(ext, double{box[t].hi[a]} - box[t].lo[a]);
      }
      e.size += ext;
      ++e.live;
    }
  });
  Extent all;
  for (const Extent& e : part) {  // chunk order: the same sum for any thread count
    for (int a = 0; a < 3; ++a) {
      all.lo[a] = std::min(all.lo[a], e.lo[a]);
      all.hi[a] = std::max(all.hi[a], e.hi[a]);
    }
    all.size += e.size;
    all.live += e.live;
  }
  result.skipped = n_tri - all.live;
  if (all.live < 2) return result;

  double h = 1.5 * all.size / static_cast<double>(all.live);
  double span = 0;
  for (int a = 0; a < 3; ++a) span = std::max(span, all.hi[a] - all.lo[a]);
  if (!(h > 0)) h = span > 0 ? span : 1.0;
  std::array<std::int64_t, 3> dims{};
  const double max_cells = std::min(4.0 * static_cast<double>(all.live) + 64.0, 2e9);
  for (;;) {
    double cells = 1;
    for (int a = 0; a < 3; ++a) {
      dims[a] = static_cast<std::int64_t>((all.hi[a] - all.lo[a]) / h) + 1;
      cells *= static_cast<double>(dims[a]);
    }
    if (cells <= max_cells) break;
    h *= 1.25;
  }
  // Monotone in x, so a box's low corner maps to its lowest cell and the low corner of the
  // intersection of two boxes to a cell both of them cover.
  auto cell_of = [&](float x, int a) {
    const auto c = static_cast<std::int64_t>((double{x} - all.lo[a]) / h);
    return std::clamp<std::int64_t>(c, 0, dims[a] - 1);
  };
  auto cell_range = [&](const Box& b, std::array<std::int64_t, 3>& lo,
                        std::array<std::int64_t, 3>& hi) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = cell_of(b.lo[a], a);
      hi[a] = cell_of(b.hi[a], a);
    }
  };

  // Count cells per triangle, scan, fill (cell << 32 | triangle) keys, sort: the keys of a cell
  // are then contiguous, its triangles ascending.
  std::vector<std::uint64_t> offset(n_tri + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_tri), [&](const auto& r) {
    std::array<std::int64_t, 3> lo, hi;
    for (std::size_t t = r.begin(); t != r.end(); ++t) {
      if (!live[t]) continue;
      cell_range(box[t], lo, hi);
      offset[t + 1] = static_cast<std::uint64_t>((hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) *
                                                 (hi[2] - lo[2] + 1));
    }
  });
  for (std::size_t t = 0; t < n_tri; ++t) offset[t + 1] += offset[t];
  std::vector<std::uint64_t> keys(offset[n_tri]);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n_tri), [&](const auto& r) {
    std::array<std::int64_t, 3> lo, hi;
    for (std::size_t t = r.begin(); t != r.end(); ++t) {
      if (!live[t]) continue;
      cell_range(box[t], lo, hi);
      std::uint64_t k = offset[t];
      for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
          for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
            keys[k++] = (static_cast<std::uint64_t>(x + dims[0] * (y + dims[1] * z)) << 32) | t;
    }
  });
  tbb::parallel_sort(keys.begin(), keys.end());
  std::vector<std::size_t> starts;  // first key of each occupied cell, then keys.size()
  for (std::size_t k = 0; k < keys.size(); ++k)
    if (k == 0 || (keys[k] >> 32) != (keys[k - 1] >> 32)) starts.push_back(k);
  starts.push_back(keys.size());

  struct Local {
    std::uint64_t pairs = 0;
    std::vector<std::array<std::uint64_t, 2>> examples;
  };
  tbb::enumerable_thread_specific<Local> locals;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, starts.size() - 1), [&](const auto& r) {
    Local& local = locals.local();
    for (std::size_t c = r.begin(); c != r.end(); ++c) {
      const std::uint64_t cell = keys[starts[c]] >> 32;
      for (std::size_t i = starts[c]; i < starts[c + 1]; ++i) {
        const auto ti = static_cast<std::uint32_t>(keys[i]);
        const Box& bi = box[ti];
        for (std::size_t j = i + 1; j < starts[c + 1]; ++j) {
          const auto tj = static_cast<std::uint32_t>(keys[j]);
          const Box& bj = box[tj];
          bool overlap = true;
          std::int64_t home[3];
          for (int a = 0; a < 3; ++a) {
            overlap = overlap && bi.lo[a] <= bj.hi[a] && bj.lo[a] <= bi.hi[a];
            home[a] = cell_of(std::max(bi.lo[a], bj.lo[a]), a);
          }
          if (!overlap ||
              static_cast<std::uint64_t>(home[0] + dims[0] * (home[1] + dims[1] * home[2])) != cell)
            continue;
          const Tri ci = corners(ti), cj = corners(tj);
          if (!triangles_intersect({pos[ci[0]], pos[ci[1]], pos[ci[2]]}, tri[ti],
                                   {pos[cj[0]], pos[cj[1]], pos[cj[2]]}, tri[tj]))
            continue;
          ++local.pairs;
          if (options.max_pairs) local.examples.push_back({std::min(ti, tj), std::max(ti, tj)});
        }
      }
    }
  });
  // Which pairs a thread meets depends on scheduling, so all are kept, then sorted and cut: the
  // smallest max_pairs, the same for any thread count.
  for (Local& local : locals) {
    result.pairs += local.pairs;
    result.examples.insert(result.examples.end(), local.examples.begin(), local.examples.end());
  }
  std::sort(result.examples.begin(), result.examples.end());
  if (result.examples.size() > options.max_pairs) result.examples.resize(options.max_pairs);
  return result;
}

}  // namespace isotile
