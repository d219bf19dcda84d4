// Everything is computed per vertex from a vertex -> incident corners table: each edge is
// examined at its lower endpoint, each fan at its centre. That keeps memory at one index per
// corner (no global edge sort) and lets all vertices be processed in parallel; every result is
// an integer count that does not depend on the order of a vertex's corners, so neither the
// table's order (which depends on scheduling) nor the thread count changes the outcome.
#include "core/mesh/mesh_topology.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/errors.h"

namespace isotile {

namespace {

struct Counts {
  std::uint64_t vertices = 0, unreferenced = 0, edges = 0, boundary = 0, border = 0,
                nonmanifold_edges = 0, nonmanifold_vertices = 0, inconsistent = 0;

  Counts& operator+=(const Counts& o) {
    vertices += o.vertices;
    unreferenced += o.unreferenced;
    edges += o.edges;
    boundary += o.boundary;
    border += o.border;
    nonmanifold_edges += o.nonmanifold_edges;
    nonmanifold_vertices += o.nonmanifold_vertices;
    inconsistent += o.inconsistent;
    return *this;
  }
};

// Lock-free union-find: a root is only ever linked below a smaller index, so no cycles form,
// and path halving only shortcuts to ancestors.
class ConcurrentUnionFind {
 public:
  explicit ConcurrentUnionFind(std::size_t n) : parent_(n) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const auto& r) {
      for (std::size_t i = r.begin(); i < r.end(); ++i) {
        parent_[i].store(static_cast<std::uint32_t>(i), std::memory_order_relaxed);
      }
    });
  }

  std::uint32_t find(std::uint32_t x) {
    for (;;) {
      std::uint32_t p = parent_[x].load(std::memory_order_acquire);
      if (p == x) return x;
      const std::uint32_t gp = parent_[p].load(std::memory_order_acquire);
      if (gp != p) parent_[x].compare_exchange_weak(p, gp, std::memory_order_acq_rel);
      x = gp;
    }
  }

  void unite(std::uint32_t a, std::uint32_t b) {
    for (;;) {
      a = find(a);
      b = find(b);
      if (a == b) return;
      if (a < b) std::swap(a, b);
      std::uint32_t expected = a;
      if (parent_[a].compare_exchange_strong(expected, b, std::memory_order_acq_rel)) return;
    }
  }

  bool is_root(std::uint32_t x) const { return parent_[x].load(std::memory_order_relaxed) == x; }

 private:
  std::vector<std::atomic<std::uint32_t>> parent_;
};

// Corners are numbered 3t + i for triangle t, then 3T + 4k + i for quad k.
template <class C>
class Corners {
 public:
  explicit Corners(const Mesh& mesh)
      : mesh_(mesh), tri_corners_(C{3} * static_cast<C>(mesh.triangles.size())) {}

  C count() const { return tri_corners_ + C{4} * static_cast<C>(mesh_.quads.size()); }

  // Vertex at the corner.
  std::uint32_t vertex(C c) const { return at(c, 0); }
  // Corners of one face have equal face numbers.
  C face(C c) const { return c < tri_corners_ ? c / 3 : tri_corners_ + (c - tri_corners_) / 4; }
  // The vertices at the next, the previous and (quads only; else the corner's own vertex) the
  // opposite corner of c's face, from one read of the face.
  std::array<std::uint32_t, 3> around(C c) const {
    if (c < tri_corners_) {
      const C t = c / 3;
      const int i = static_cast<int>(c - 3 * t);
      const Tri& f = mesh_.triangles[t];
      return {f[(i + 1) % 3], f[(i + 2) % 3], f[i]};
    }
    const C q = (c - tri_corners_) / 4;
    const int i = static_cast<int>(c - tri_corners_ - 4 * q);
    const Quad& f = mesh_.quads[q];
    return {f[(i + 1) % 4], f[(i + 3) % 4], f[(i + 2) % 4]};
  }
  // Where face c lies, to fetch it ahead of its use.
  const void* address(C c) const {
    if (c < tri_corners_) return &mesh_.triangles[c / 3];
    return &mesh_.quads[(c - tri_corners_) / 4];
  }

 private:
  std::uint32_t at(C c, int step) const {
    if (c < tri_corners_) {
      const C t = c / 3;
      const int i = static_cast<int>(c - 3 * t);
      return mesh_.triangles[t][(i + 3 + step) % 3];
    }
    const C q = (c - tri_corners_) / 4;
    const int i = static_cast<int>(c - tri_corners_ - 4 * q);
    return mesh_.quads[q][(i + 4 + step) % 4];
  }

  const Mesh& mesh_;
  C tri_corners_;
};

bool on_border(const Vec3f& a, const Vec3f& b, const std::array<Vec3f, 2>& box,
               const std::array<Vec3f, 2>& inner) {
  for (int axis = 0; axis < 3; ++axis) {
    const float lo = box[0][axis], hi = box[1][axis];
    const float in_lo = inner[0][axis], in_hi = inner[1][axis];
    if (a[axis] >= lo && a[axis] <= in_lo && b[axis] >= lo && b[axis] <= in_lo) return true;
    if (a[axis] <= hi && a[axis] >= in_hi && b[axis] <= hi && b[axis] >= in_hi) return true;
  }
  return false;
}

constexpr std::size_t kPrefetchVertices = 8;

// Smallest local union-find, for the faces around one vertex.
std::size_t local_find(std::vector<std::size_t>& parent, std::size_t x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

template <class C>
TopologyStats compute(const Mesh& mesh, const TopologyOptions& options) {
  const Corners<C> corners(mesh);
  const C ncorners = corners.count();
  const std::size_t nv = mesh.positions.size();

  // vertex -> incident corners, as one array (a counting sort). `bound` counts, is scanned into
  // each vertex's first slot and is advanced by the fill, after which bound[v] is the end of v's
  // corners and bound[v - 1] their beginning.
  std::vector<std::atomic<C>> bound(nv);
  auto incident = std::make_unique_for_overwrite<C[]>(ncorners);
  tbb::parallel_for(tbb::blocked_range<C>(0, ncorners, 1 << 14), [&](const auto& r) {
    for (C c = r.begin(); c < r.end(); ++c) {
      bound[corners.vertex(c)].fetch_add(1, std::memory_order_relaxed);
    }
  });
  {
    C sum = 0;
    for (std::size_t v = 0; v < nv; ++v) {
      const C count = bound[v].load(std::memory_order_relaxed);
      bound[v].store(sum, std::memory_order_relaxed);
      sum += count;
    }
  }
  tbb::parallel_for(tbb::blocked_range<C>(0, ncorners, 1 << 14), [&](const auto& r) {
    for (C c = r.begin(); c < r.end(); ++c) {
      incident[bound[corners.vertex(c)].fetch_add(1, std::memory_order_relaxed)] = c;
    }
  });
  auto first_of = [&](std::size_t v) -> C {
    return v == 0 ? C{0} : bound[v - 1].load(std::memory_order_relaxed);
  };
  auto last_of = [&](std::size_t v) -> C { return bound[v].load(std::memory_order_relaxed); };

  const auto& pos = mesh.positions;
  const Counts counts = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, nv, 1 << 12), Counts{},
      [&](const tbb::blocked_range<std::size_t>& r, Counts sum) {
        // One entry per (corner at v, neighbour across an edge of its face at v):
        // neighbour << 32 | local corner << 1 | 1 when the face runs v -> neighbour. Sorted, the
        // entries of one neighbour are adjacent: the edge's faces and the fan's links at once.
        std::vector<std::uint64_t> entries;
        std::vector<std::size_t> parent;
        for (std::size_t vi = r.begin(); vi < r.end(); ++vi) {
          const auto v = static_cast<std::uint32_t>(vi);
          const C* first = incident.get() + first_of(vi);
          const C* last = incident.get() + last_of(vi);
          if (first == last) {
            ++sum.unreferenced;
            continue;
          }
          ++sum.vertices;
          const std::size_t degree = static_cast<std::size_t>(last - first);
          if (degree >= (std::size_t{1} << 31))
            throw CapacityError("vertex " + std::to_string(v) + " has " + std::to_string(degree) +
                                " face corners, more than the topology measure can count");

          // A face's edge v-w is seen from v's corner either leaving v (w = next) or entering it
          // (w = prev). The self-edge of a face that repeats v is taken once, as leaving.
          // The faces around a vertex lie far apart in memory; the next vertices' faces are
          // fetched while this one's are examined.
          if (vi + kPrefetchVertices < r.end()) {
            const C* ahead = incident.get() + first_of(vi + kPrefetchVertices);
            const C* ahead_end = incident.get() + last_of(vi + kPrefetchVertices);
            for (; ahead != ahead_end; ++ahead) __builtin_prefetch(corners.address(*ahead));
          }
          entries.clear();
          bool repeats = false;
          for (std::size_t i = 0; i < degree; ++i) {
            const auto [n, p, o] = corners.around(first[i]);
            entries.push_back(std::uint64_t{n} << 32 | std::uint64_t{i} << 1 | 1);
            if (p != v) entries.push_back(std::uint64_t{p} << 32 | std::uint64_t{i} << 1);
            repeats = repeats || n == v || p == v || o == v;
          }
          std::sort(entries.begin(), entries.end());

          const bool fans = degree > 1;
          if (fans) {
            parent.resize(degree);
            for (std::size_t i = 0; i < degree; ++i) parent[i] = i;
          }
          // A face that visits v twice is still one face.
          if (fans && repeats) {
            for (std::size_t i = 0; i < degree; ++i) {
              const auto [n, p, o] = corners.around(first[i]);
              if (n != v && p != v && o != v) continue;
              for (std::size_t j = 0; j < i; ++j) {
                if (corners.face(first[j]) == corners.face(first[i])) {
                  parent[local_find(parent, i)] = local_find(parent, j);
                }
              }
            }
          }
          // An edge belongs to its lower endpoint (the self-edge to its only one); faces around
          // v are one fan when linked through edges at v to other vertices.
          for (std::size_t i = 0; i < entries.size();) {
            const auto w = static_cast<std::uint32_t>(entries[i] >> 32);
            std::size_t j = i + 1;
            while (j < entries.size() && static_cast<std::uint32_t>(entries[j] >> 32) == w) ++j;
            if (w >= v) {
              ++sum.edges;
              if (j - i == 1) {
                ++sum.boundary;
                if (options.border_box &&
                    on_border(pos[v], pos[w], *options.border_box,
                              options.border_inner.value_or(*options.border_box))) {
                  ++sum.border;
                }
              } else if (j - i > 2) {
                ++sum.nonmanifold_edges;
              } else if ((entries[i] & 1) == (entries[i + 1] & 1)) {
                ++sum.inconsistent;
              }
            }
            if (fans && w != v) {
              for (std::size_t k = i + 1; k < j; ++k) {
                const std::size_t a = local_find(parent, (entries[k] >> 1) & 0x7fffffff);
                const std::size_t b = local_find(parent, (entries[k - 1] >> 1) & 0x7fffffff);
                if (a != b) parent[a] = b;
              }
            }
            i = j;
          }
          if (!fans) continue;
          std::size_t roots = 0;
          for (std::size_t i = 0; i < degree && roots < 2; ++i) roots += parent[i] == i;
          if (roots > 1) ++sum.nonmanifold_vertices;
        }
        return sum;
      },
      [](Counts a, const Counts& b) { return a += b; });

  ConcurrentUnionFind components(nv);
  auto join = [&](const auto& faces) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, faces.size(), 1 << 14),
                      [&](const auto& r) {
                        for (std::size_t f = r.begin(); f < r.end(); ++f) {
                          for (std::size_t i = 1; i < faces[f].size(); ++i) {
                            components.unite(faces[f][0], faces[f][i]);
                          }
                        }
                      });
  };
  join(mesh.triangles);
  join(mesh.quads);
  // Only referenced vertices are ever joined, so a set's root is referenced exactly when the set
  // has faces; unreferenced vertices stay roots of their own and are left out.
  const std::uint64_t ncomponents = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, nv, 1 << 14), std::uint64_t{0},
      [&](const tbb::blocked_range<std::size_t>& r, std::uint64_t n) {
        for (std::size_t v = r.begin(); v < r.end(); ++v) {
          if (last_of(v) != first_of(v) && components.is_root(static_cast<std::uint32_t>(v))) {
            ++n;
          }
        }
        return n;
      },
      [](std::uint64_t a, std::uint64_t b) { return a + b; });

  TopologyStats s;
  s.vertices = counts.vertices;
  s.unreferenced_vertices = counts.unreferenced;
  s.edges = counts.edges;
  s.faces = mesh.triangles.size() + mesh.quads.size();
  s.boundary_edges = counts.boundary;
  s.border_boundary_edges = counts.border;
  s.nonmanifold_edges = counts.nonmanifold_edges;
  s.nonmanifold_vertices = counts.nonmanifold_vertices;
  s.inconsistently_oriented_edges = counts.inconsistent;
  s.euler = static_cast<std::int64_t>(s.vertices) - static_cast<std::int64_t>(s.edges) +
            static_cast<std::int64_t>(s.faces);
  s.components = ncomponents;
  s.closed = s.boundary_edges == 0 && s.nonmanifold_edges == 0;
  s.watertight = s.boundary_edges == s.border_boundary_edges && s.nonmanifold_edges == 0;
  return s;
}

}  // namespace

TopologyStats mesh_topology(const Mesh& mesh, const TopologyOptions& options) {
  check_face_indices(mesh);
  const std::uint64_t corners =
      3 * std::uint64_t{mesh.triangles.size()} + 4 * std::uint64_t{mesh.quads.size()};
  // 32-bit corner numbers halve the memory of the incidence table whenever they suffice.
  if (corners < std::numeric_limits<std::uint32_t>::max()) {
    return compute<std::uint32_t>(mesh, options);
  }
  return compute<std::uint64_t>(mesh, options);
}

}  // namespace isotile
