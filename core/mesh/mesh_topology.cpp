// Everything is computed per vertex from the corners around it: each edge is examined at its
// lower endpoint, each fan at its centre, so every result is an integer count that depends
// neither on the order in which vertices are visited nor on the order of a vertex's corners.
//
// The faces are cut into chunks of consecutive faces. Extractors emit faces cell by cell and
// number vertices as they go, so nearly every vertex has all its faces in one chunk; such a vertex
// is examined while its chunk is processed, from a corner table local to the chunk that stays in
// the thread's scratch memory. Only the few vertices whose faces span chunks ("shared" here) go
// through a global corner table. A global vertex -> incident corners table would cost one index
// per corner (2.2 GB for 180M triangles, all of it freshly faulted memory, filled with an atomic
// per corner and read back from all over the triangle array). Chunks are processed in parallel;
// which thread takes which chunk changes nothing but the time.
//
// Connected components follow the same split: a union-find over each chunk's own vertices, and
// one over the shared vertices only, linked wherever a chunk's component touches them.
#include "core/mesh/mesh_topology.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/errors.h"

namespace isotile {

namespace {

struct Counts {
  std::uint64_t vertices = 0, edges = 0, boundary = 0, border = 0, nonmanifold_edges = 0,
                nonmanifold_vertices = 0, inconsistent = 0, components = 0;

  Counts& operator+=(const Counts& o) {
    vertices += o.vertices;
    edges += o.edges;
    boundary += o.boundary;
    border += o.border;
    nonmanifold_edges += o.nonmanifold_edges;
    nonmanifold_vertices += o.nonmanifold_vertices;
    inconsistent += o.inconsistent;
    components += o.components;
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
        parent_[i].store(static_cast<std::uint64_t>(i), std::memory_order_relaxed);
      }
    });
  }

  std::uint64_t find(std::uint64_t x) {
    for (;;) {
      std::uint64_t p = parent_[x].load(std::memory_order_acquire);
      if (p == x) return x;
      const std::uint64_t gp = parent_[p].load(std::memory_order_acquire);
      if (gp != p) parent_[x].compare_exchange_weak(p, gp, std::memory_order_acq_rel);
      x = gp;
    }
  }

  void unite(std::uint64_t a, std::uint64_t b) {
    for (;;) {
      a = find(a);
      b = find(b);
      if (a == b) return;
      if (a < b) std::swap(a, b);
      std::uint64_t expected = a;
      if (parent_[a].compare_exchange_strong(expected, b, std::memory_order_acq_rel)) return;
    }
  }

  bool is_root(std::uint64_t x) const { return parent_[x].load(std::memory_order_relaxed) == x; }

 private:
  std::vector<std::atomic<std::uint64_t>> parent_;
};

// Faces are numbered triangles first, then quads; corners 3t + i for triangle t, then
// 3T + 4k + i for quad k, so the corners of consecutive faces are consecutive.
template <class C>
class Corners {
 public:
  explicit Corners(const Mesh& mesh)
      : mesh_(mesh),
        ntri_(mesh.triangles.size()),
        tri_corners_(C{3} * static_cast<C>(mesh.triangles.size())) {}

  C count() const { return tri_corners_ + C{4} * static_cast<C>(mesh_.quads.size()); }
  std::size_t faces() const { return ntri_ + mesh_.quads.size(); }
  C first_corner(std::size_t f) const {
    return f < ntri_ ? C{3} * static_cast<C>(f) : tri_corners_ + C{4} * static_cast<C>(f - ntri_);
  }
  // Calls fn(first corner, vertices, count) for faces [begin, end).
  template <class Fn>
  void for_faces(std::size_t begin, std::size_t end, Fn&& fn) const {
    for (std::size_t f = begin; f < std::min(end, ntri_); ++f) {
      fn(C{3} * static_cast<C>(f), mesh_.triangles[f].data(), 3);
    }
    for (std::size_t f = std::max(begin, ntri_); f < end; ++f) {
      fn(tri_corners_ + C{4} * static_cast<C>(f - ntri_), mesh_.quads[f - ntri_].data(), 4);
    }
  }

  // Corners of one face have equal face numbers.
  C face(C c) const { return c < tri_corners_ ? c / 3 : tri_corners_ + (c - tri_corners_) / 4; }
  // The vertices at the next, the previous and the opposite corner of c's face (a triangle has
  // none: its next one again), from one read of the face. The face visits c's vertex twice
  // exactly when one of them is that vertex.
  std::array<std::uint32_t, 3> around(C c) const {
    if (c < tri_corners_) {
      const C t = c / 3;
      const int i = static_cast<int>(c - 3 * t);
      const Tri& f = mesh_.triangles[t];
      return {f[(i + 1) % 3], f[(i + 2) % 3], f[(i + 1) % 3]};
    }
    const C q = (c - tri_corners_) / 4;
    const int i = static_cast<int>(c - tri_corners_ - 4 * q);
    const Quad& f = mesh_.quads[q];
    return {f[(i + 1) % 4], f[(i + 3) % 4], f[(i + 2) % 4]};
  }

 private:
  const Mesh& mesh_;
  std::size_t ntri_;
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

struct Context {
  const std::vector<Vec3f>& positions;
  const TopologyOptions& options;

  // A boundary edge v-w (found once, at its lower endpoint).
  void boundary(std::uint32_t v, std::uint32_t w, Counts& sum) const {
    ++sum.boundary;
    if (options.border_box && on_border(positions[v], positions[w], *options.border_box,
                                        options.border_inner.value_or(*options.border_box))) {
      ++sum.border;
    }
  }
};

// Smallest local union-find, for the faces around one vertex.
std::size_t local_find(std::vector<std::size_t>& parent, std::size_t x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

struct VertexScratch {
  std::vector<std::uint64_t> entries;
  std::vector<std::size_t> parent;
};

// Any vertex: its `degree` corners are at(0), ..., at(degree - 1).
template <class C, class At>
void examine_general(std::uint32_t v, std::size_t degree, At at, const Corners<C>& corners,
                     const Context& ctx, VertexScratch& scratch, Counts& sum) {
  if (degree >= (std::size_t{1} << 31))
    throw CapacityError("vertex " + std::to_string(v) + " has " + std::to_string(degree) +
                        " face corners, more than the topology measure can count");
  // One entry per (corner at v, neighbour across an edge of its face at v):
  // neighbour << 32 | local corner << 1 | 1 when the face runs v -> neighbour. Sorted, the
  // entries of one neighbour are adjacent: the edge's faces and the fan's links at once.
  // A face's edge v-w is seen from v's corner either leaving v (w = next) or entering it
  // (w = prev). The self-edge of a face that repeats v is taken once, as leaving.
  auto& entries = scratch.entries;
  auto& parent = scratch.parent;
  entries.clear();
  bool repeats = false;
  for (std::size_t i = 0; i < degree; ++i) {
    const auto [n, p, o] = corners.around(at(i));
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
      const auto [n, p, o] = corners.around(at(i));
      if (n != v && p != v && o != v) continue;
      for (std::size_t j = 0; j < i; ++j) {
        if (corners.face(at(j)) == corners.face(at(i))) {
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
        ctx.boundary(v, w, sum);
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
  if (!fans) return;
  std::size_t roots = 0;
  for (std::size_t i = 0; i < degree && roots < 2; ++i) roots += parent[i] == i;
  if (roots > 1) ++sum.nonmanifold_vertices;
}

using Side = std::array<std::uint32_t, 2>;

// The vertices at the next and the previous corner of corner c's face.
template <class C>
Side side_of(C c, const Corners<C>& corners) {
  const auto [n, p, o] = corners.around(c);
  return {n, p};
}

constexpr std::size_t kFastDegree = 16;
// examine_fast() reads up to this many sides past a vertex's last one.
constexpr std::size_t kSideSlack = 3;

#if defined(__SSE2__)
// Bit j set where lane j of the first `blocks` vectors equals x.
inline std::uint32_t equal_mask(const __m128i* lanes, std::size_t blocks, std::uint32_t x) {
  const __m128i key = _mm_set1_epi32(static_cast<int>(x));
  std::uint32_t mask = 0;
  for (std::size_t b = 0; b < blocks; ++b) {
    const __m128i eq = _mm_cmpeq_epi32(lanes[b], key);
    mask |= static_cast<std::uint32_t>(_mm_movemask_ps(_mm_castsi128_ps(eq))) << (4 * b);
  }
  return mask;
}
#else
inline std::uint32_t equal_mask(const std::uint32_t* lanes, std::size_t blocks, std::uint32_t x) {
  std::uint32_t mask = 0;
  for (std::size_t j = 0; j < 4 * blocks; ++j) mask |= std::uint32_t{lanes[j] == x} << j;
  return mask;
}
#endif

// The common vertex: at most kFastDegree faces, no edge from v to itself, every edge at v with
// one face or two opposite ones. Then the faces around v form chains (open fans) and cycles
// (closed fans) through "the face after corner i is the one entering v from i's next vertex",
// found by comparing all next and previous vertices at once instead of sorting. (A quad visiting
// v at opposite corners passes: its two corners follow each other through the vertex between
// them, so they are in one fan, as examine_general() has them.) Returns false, having counted
// nothing, for any other vertex. `sides` holds the side_of() of v's corners and kSideSlack
// readable entries after them.
inline bool examine_fast(std::uint32_t v, std::size_t degree, const Side* sides, const Context& ctx,
                         Counts& sum) {
  if (degree > kFastDegree) return false;
  const std::size_t blocks = (degree + 3) / 4;
  // Lanes past the degree hold v, which is nobody's neighbour here, so they match nothing.
  alignas(16) std::uint32_t next[kFastDegree], prev[kFastDegree];
#if defined(__SSE2__)
  // Loaded and split in registers: storing the sides one by one and loading them as vectors
  // would stall on every load (no store forwarding from narrower stores).
  __m128i nexts[kFastDegree / 4], prevs[kFastDegree / 4];
  const __m128i self = _mm_set1_epi32(static_cast<int>(v));
  __m128i repeats = _mm_setzero_si128();
  for (std::size_t b = 0; b < blocks; ++b) {
    const __m128 q0 = _mm_loadu_ps(reinterpret_cast<const float*>(sides + 4 * b));
    const __m128 q1 = _mm_loadu_ps(reinterpret_cast<const float*>(sides + 4 * b + 2));
    const __m128i n = _mm_castps_si128(_mm_shuffle_ps(q0, q1, _MM_SHUFFLE(2, 0, 2, 0)));
    const __m128i p = _mm_castps_si128(_mm_shuffle_ps(q0, q1, _MM_SHUFFLE(3, 1, 3, 1)));
    const __m128i lane =
        _mm_add_epi32(_mm_set1_epi32(static_cast<int>(4 * b)), _mm_setr_epi32(0, 1, 2, 3));
    const __m128i real = _mm_cmplt_epi32(lane, _mm_set1_epi32(static_cast<int>(degree)));
    repeats = _mm_or_si128(repeats, _mm_and_si128(real, _mm_or_si128(_mm_cmpeq_epi32(n, self),
                                                                     _mm_cmpeq_epi32(p, self))));
    nexts[b] = _mm_or_si128(_mm_and_si128(real, n), _mm_andnot_si128(real, self));
    prevs[b] = _mm_or_si128(_mm_and_si128(real, p), _mm_andnot_si128(real, self));
    _mm_store_si128(reinterpret_cast<__m128i*>(next + 4 * b), nexts[b]);
    _mm_store_si128(reinterpret_cast<__m128i*>(prev + 4 * b), prevs[b]);
  }
  if (_mm_movemask_epi8(repeats) != 0) return false;
#else
  for (std::size_t i = 0; i < 4 * blocks; ++i) {
    next[i] = i < degree ? sides[i][0] : v;
    prev[i] = i < degree ? sides[i][1] : v;
    if (i < degree && (next[i] == v || prev[i] == v)) return false;
  }
  const std::uint32_t* nexts = next;
  const std::uint32_t* prevs = prev;
#endif
  // Row i of the next == previous matrix: the corners whose face enters v from next[i]. Every
  // edge at v has one face or two opposite ones when no row and no column has two bits, and no
  // two next (or previous) vertices are equal. Equal next vertices have equal rows, so only
  // those with empty rows (boundary edges) can still be equal past the first test; likewise
  // previous vertices with empty columns.
  std::uint8_t after[kFastDegree];
  std::uint32_t entered = 0;  // corners whose face follows another's around v
  std::uint32_t open = 0;     // corners whose face no other follows
  std::uint32_t twice = 0;
  for (std::size_t i = 0; i < degree; ++i) {
    const std::uint32_t match = equal_mask(prevs, blocks, next[i]);
    twice |= (match & (match - 1)) | (entered & match);
    entered |= match;
    open |= std::uint32_t{match == 0} << i;
    after[i] = match ? static_cast<std::uint8_t>(std::countr_zero(match)) : kFastDegree;
  }
  if (twice) return false;
  const std::uint32_t all = (std::uint32_t{1} << degree) - 1;
  const std::uint32_t heads = all & ~entered;
  if (open & (open - 1)) {
    for (std::uint32_t m = open; m; m &= m - 1) {
      const int i = std::countr_zero(m);
      if ((equal_mask(nexts, blocks, next[i]) & open) != (std::uint32_t{1} << i)) return false;
    }
  }
  if (heads & (heads - 1)) {
    for (std::uint32_t m = heads; m; m &= m - 1) {
      const int i = std::countr_zero(m);
      if ((equal_mask(prevs, blocks, prev[i]) & heads) != (std::uint32_t{1} << i)) return false;
    }
  }
  Counts here;
  for (std::size_t i = 0; i < degree; ++i) {
    if (next[i] > v) {
      ++here.edges;
      if (after[i] == kFastDegree) ctx.boundary(v, next[i], here);
    }
    // An edge entering v that no face leaves v by: a boundary edge of its own.
    if ((heads >> i & 1) != 0 && prev[i] > v) {
      ++here.edges;
      ctx.boundary(v, prev[i], here);
    }
  }
  if (degree > 1) {
    bool one_fan = std::popcount(heads) <= 1;
    if (one_fan) {
      // From the chain's head (or anywhere on a cycle) the fan must reach every face.
      const std::size_t start = heads ? std::countr_zero(heads) : 0;
      std::size_t reached = 1;
      for (std::size_t i = after[start]; i != kFastDegree && i != start && reached <= degree;
           i = after[i]) {
        ++reached;
      }
      one_fan = reached == degree;
    }
    if (!one_fan) ++here.nonmanifold_vertices;
  }
  sum += here;
  return true;
}

// Vertex v with `degree` corners: at(i) is corner i; `sides` as for examine_fast().
template <class C, class At>
void examine(std::uint32_t v, std::size_t degree, At at, const Side* sides,
             const Corners<C>& corners, const Context& ctx, VertexScratch& scratch, Counts& sum) {
  ++sum.vertices;
  if (!examine_fast(v, degree, sides, ctx, sum)) {
    examine_general(v, degree, at, corners, ctx, scratch, sum);
  }
}

// Per-vertex state, one word a vertex. Before the chunk pass: unreferenced, shared by several
// chunks, or the one chunk that has all its faces. Then shared vertices are numbered (kShared
// flag), and during its chunk pass a chunk numbers its own vertices (kOwn flag).
template <class S>
struct State {
  static constexpr S kUnreferenced = std::numeric_limits<S>::max();
  static constexpr S kSeveral = kUnreferenced - 1;
  static constexpr S kShared = S{1} << (8 * sizeof(S) - 1);
  static constexpr S kOwn = S{1} << (8 * sizeof(S) - 2);
  static constexpr S kFlags = kShared | kOwn;
  // Chunk numbers and a chunk's own vertices stay below kOwn, shared vertices below kSeveral.
};

// A chunk's scratch, kept per thread from chunk to chunk (its memory is faulted in once).
struct ChunkScratch {
  std::vector<std::uint32_t> own_of_corner;  // the corner's vertex numbered in the chunk, or kNone
  std::vector<std::uint32_t> global;         // own vertex -> mesh vertex
  std::vector<std::uint32_t> bound;          // own vertex -> end of its corners' sides
  std::vector<Side> sides;                   // own vertices' corners' side_of(), grouped
  std::vector<std::uint32_t> slow;           // own vertices examine_fast() declined
  std::vector<std::uint64_t> slow_corners;   // their corners: slow index << 32 | chunk corner
  std::vector<std::uint32_t> parent;         // union-find over own vertices
  std::vector<std::uint64_t> link;           // own root -> a shared vertex in its component
  VertexScratch vertex;
};

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr std::uint64_t kNoLink = std::numeric_limits<std::uint64_t>::max();

std::uint32_t find_root(std::vector<std::uint32_t>& parent, std::uint32_t x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

// What one chunk hands to the shared pass.
template <class C, class S>
struct ChunkResult {
  Counts counts;
  std::vector<std::pair<S, C>> shared_corners;  // (shared number, corner)
  std::vector<std::pair<S, S>> shared_links;    // shared vertices in one component
};

std::size_t chunk_faces(const TopologyOptions& options, std::size_t faces) {
  std::size_t size = options.chunk_faces;
  if (size == 0) {
    // The faces of a vertex lie up to about one slice of cells apart in an extractor's output,
    // and a slice of a volume holds about faces^(2/3) of them. Chunks of 8 slices leave a few
    // percent of the vertices shared (bonsai tiled to 1024x1024x512 and 2048x2048x1024: 22M and
    // 181M triangles, chunks of 0.64M and 2.56M faces, 6.3% shared in both) while a thread's
    // scratch (about 46 bytes a face, faulted in on first use) stays small. When chosen, at 22M
    // triangles, chunks of 0.5M-1M faces were fastest, 4M took 30% longer, 256k 15% longer.
    const double slice = std::cbrt(static_cast<double>(faces) * static_cast<double>(faces));
    size =
        std::clamp(static_cast<std::size_t>(8 * slice), std::size_t{1} << 16, std::size_t{1} << 22);
  }
  // Room for the state's chunk numbers and a chunk's corner numbers.
  size = std::max(size, faces >> 28);
  return std::min(size, std::size_t{1} << 26);
}

template <class C, class S>
TopologyStats compute(const Mesh& mesh, const TopologyOptions& options) {
  using St = State<S>;
  const Corners<C> corners(mesh);
  const std::size_t nv = mesh.positions.size();
  const std::size_t nfaces = corners.faces();
  const std::size_t chunk = chunk_faces(options, nfaces);
  const std::size_t nchunks = (nfaces + chunk - 1) / chunk;
  const Context ctx{mesh.positions, options};

  auto state = std::make_unique_for_overwrite<S[]>(nv);
  auto state_at = [&](std::uint32_t v) { return std::atomic_ref<S>(state[v]); };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 1 << 16), [&](const auto& r) {
    std::fill(state.get() + r.begin(), state.get() + r.end(), St::kUnreferenced);
  });

  // Which chunk has all the faces of each vertex. The outcome (one chunk, or kSeveral when two
  // or more touch it) does not depend on which chunk gets there first.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nchunks, 1), [&](const auto& r) {
    for (std::size_t c = r.begin(); c < r.end(); ++c) {
      const S self = static_cast<S>(c);
      corners.for_faces(c * chunk, std::min(nfaces, (c + 1) * chunk),
                        [&](C, const std::uint32_t* f, int n) {
                          for (int k = 0; k < n; ++k) {
                            auto s = state_at(f[k]);
                            S seen = s.load(std::memory_order_relaxed);
                            if (seen == self || seen == St::kSeveral) continue;
                            if (seen == St::kUnreferenced &&
                                s.compare_exchange_strong(seen, self, std::memory_order_relaxed)) {
                              continue;
                            }
                            if (seen != self) s.store(St::kSeveral, std::memory_order_relaxed);
                          }
                        });
    }
  });

  // Number the shared vertices in vertex order, in fixed blocks.
  constexpr std::size_t kBlock = 1 << 16;
  const std::size_t nblocks = (nv + kBlock - 1) / kBlock;
  std::vector<std::uint64_t> block_shared(nblocks + 1, 0), block_unreferenced(nblocks, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nblocks, 1), [&](const auto& r) {
    for (std::size_t b = r.begin(); b < r.end(); ++b) {
      std::uint64_t shared = 0, unreferenced = 0;
      for (std::size_t v = b * kBlock; v < std::min(nv, (b + 1) * kBlock); ++v) {
        shared += state[v] == St::kSeveral;
        unreferenced += state[v] == St::kUnreferenced;
      }
      block_shared[b + 1] = shared;
      block_unreferenced[b] = unreferenced;
    }
  });
  for (std::size_t b = 0; b < nblocks; ++b) block_shared[b + 1] += block_shared[b];
  const std::uint64_t nshared = block_shared[nblocks];
  std::uint64_t unreferenced = 0;
  for (std::uint64_t u : block_unreferenced) unreferenced += u;
  std::vector<std::uint32_t> shared_vertex(nshared);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nblocks, 1), [&](const auto& r) {
    for (std::size_t b = r.begin(); b < r.end(); ++b) {
      std::uint64_t k = block_shared[b];
      for (std::size_t v = b * kBlock; v < std::min(nv, (b + 1) * kBlock); ++v) {
        if (state[v] != St::kSeveral) continue;
        shared_vertex[k] = static_cast<std::uint32_t>(v);
        state[v] = St::kShared | static_cast<S>(k++);
      }
    }
  });

  // The chunk pass: each chunk's own vertices examined, its components found, its corners at
  // shared vertices counted and handed on.
  std::vector<std::atomic<C>> shared_bound(nshared);
  std::vector<ChunkResult<C, S>> results(nchunks);
  tbb::enumerable_thread_specific<ChunkScratch> scratches;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nchunks, 1), [&](const auto& r) {
    ChunkScratch& sc = scratches.local();
    for (std::size_t c = r.begin(); c < r.end(); ++c) {
      ChunkResult<C, S>& out = results[c];
      const std::size_t f0 = c * chunk, f1 = std::min(nfaces, (c + 1) * chunk);
      const C base = corners.first_corner(f0);
      const auto ncorners = static_cast<std::size_t>(
          (f1 == nfaces ? corners.count() : corners.first_corner(f1)) - base);
      const S self = static_cast<S>(c);
      sc.own_of_corner.resize(ncorners);
      sc.global.clear();
      sc.bound.clear();
      sc.parent.clear();
      sc.link.clear();
      Counts& sum = out.counts;
      auto join_shared = [&](std::uint64_t a, std::uint64_t b) {
        out.shared_links.emplace_back(static_cast<S>(a), static_cast<S>(b));
      };

      // Number own vertices in order of first use, count their corners, join components.
      corners.for_faces(f0, f1, [&](C first, const std::uint32_t* f, int size) {
        std::uint32_t root = kNone;
        std::uint64_t first_shared = kNoLink;
        for (int k = 0; k < size; ++k) {
          const auto corner = static_cast<std::size_t>(first + k - base);
          auto s = state_at(f[k]);
          const S seen = s.load(std::memory_order_relaxed);
          std::uint32_t own;
          if (seen == self) {
            own = static_cast<std::uint32_t>(sc.global.size());
            s.store(St::kOwn | static_cast<S>(own), std::memory_order_relaxed);
            sc.global.push_back(f[k]);
            sc.bound.push_back(0);
            sc.parent.push_back(own);
            sc.link.push_back(kNoLink);
          } else if ((seen & St::kFlags) == St::kOwn) {
            own = static_cast<std::uint32_t>(seen & ~St::kFlags);
          } else {
            const S k_shared = seen & ~St::kFlags;
            sc.own_of_corner[corner] = kNone;
            out.shared_corners.emplace_back(k_shared, first + k);
            shared_bound[k_shared].fetch_add(1, std::memory_order_relaxed);
            if (first_shared == kNoLink) {
              first_shared = k_shared;
            } else if (first_shared != k_shared) {
              join_shared(first_shared, k_shared);
            }
            continue;
          }
          sc.own_of_corner[corner] = own;
          ++sc.bound[own];
          const std::uint32_t r_own = find_root(sc.parent, own);
          if (root == kNone) {
            root = r_own;
          } else if (r_own != root) {
            // Keep the smaller root; a component reaching two shared vertices links them.
            const std::uint32_t keep = std::min(root, r_own), gone = std::max(root, r_own);
            sc.parent[gone] = keep;
            if (sc.link[keep] == kNoLink) {
              sc.link[keep] = sc.link[gone];
            } else if (sc.link[gone] != kNoLink && sc.link[gone] != sc.link[keep]) {
              join_shared(sc.link[keep], sc.link[gone]);
            }
            root = keep;
          }
        }
        if (root != kNone && first_shared != kNoLink) {
          if (sc.link[root] == kNoLink) {
            sc.link[root] = first_shared;
          } else if (sc.link[root] != first_shared) {
            join_shared(sc.link[root], first_shared);
          }
        }
      });
      const std::size_t nown = sc.global.size();
      for (std::uint32_t i = 0; i < nown; ++i) {
        if (sc.parent[i] == i && sc.link[i] == kNoLink) ++sum.components;
      }

      // Own vertices' corners, grouped (a counting sort: bound[i] ends up at the end of own
      // vertex i's corners, bound[i - 1] at their beginning).
      {
        std::uint32_t total = 0;
        for (std::size_t i = 0; i < nown; ++i) {
          total += sc.bound[i];
          sc.bound[i] = total - sc.bound[i];
        }
        sc.sides.resize(total + kSideSlack);
      }
      // Read in face order, written in vertex order: examining a vertex then reads its corners'
      // sides in sequence, not faces from all over the chunk.
      corners.for_faces(f0, f1, [&](C first, const std::uint32_t* f, int size) {
        for (int k = 0; k < size; ++k) {
          const auto corner = static_cast<std::uint32_t>(first + k - base);
          const std::uint32_t own = sc.own_of_corner[corner];
          if (own == kNone) continue;
          sc.sides[sc.bound[own]++] = {f[(k + 1) % size], f[(k + size - 1) % size]};
        }
      });
      sc.slow.clear();
      for (std::size_t i = 0; i < nown; ++i) {
        const std::uint32_t first = i == 0 ? 0 : sc.bound[i - 1];
        if (!examine_fast(sc.global[i], sc.bound[i] - first, sc.sides.data() + first, ctx, sum)) {
          sc.slow.push_back(static_cast<std::uint32_t>(i));
        }
      }
      sum.vertices += nown;
      // The rare vertices the fast path declines need their corners, not only the sides:
      // gathered by one more scan of the chunk (bound is free again, and numbers them).
      if (!sc.slow.empty()) {
        std::fill(sc.bound.begin(), sc.bound.begin() + nown, kNone);
        for (std::size_t j = 0; j < sc.slow.size(); ++j) {
          sc.bound[sc.slow[j]] = static_cast<std::uint32_t>(j);
        }
        sc.slow_corners.clear();
        for (std::size_t k = 0; k < ncorners; ++k) {
          const std::uint32_t own = sc.own_of_corner[k];
          if (own != kNone && sc.bound[own] != kNone) {
            sc.slow_corners.push_back(std::uint64_t{sc.bound[own]} << 32 | k);
          }
        }
        std::sort(sc.slow_corners.begin(), sc.slow_corners.end());
        for (std::size_t a = 0; a < sc.slow_corners.size();) {
          const std::uint64_t j = sc.slow_corners[a] >> 32;
          std::size_t b = a + 1;
          while (b < sc.slow_corners.size() && sc.slow_corners[b] >> 32 == j) ++b;
          const std::uint64_t* at = sc.slow_corners.data() + a;
          examine_general(
              sc.global[sc.slow[j]], b - a,
              [&](std::size_t i) { return base + static_cast<C>(at[i] & 0xffffffff); }, corners,
              ctx, sc.vertex, sum);
          a = b;
        }
      }
    }
  });

  // Shared vertices: their corners from every chunk, grouped the same way.
  C shared_corners = 0;
  for (auto& b : shared_bound) {
    const C n = b.load(std::memory_order_relaxed);
    b.store(shared_corners, std::memory_order_relaxed);
    shared_corners += n;
  }
  auto shared_incident =
      std::make_unique_for_overwrite<C[]>(static_cast<std::size_t>(shared_corners));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nchunks, 1), [&](const auto& r) {
    for (std::size_t c = r.begin(); c < r.end(); ++c) {
      for (const auto& [k, corner] : results[c].shared_corners) {
        shared_incident[shared_bound[k].fetch_add(1, std::memory_order_relaxed)] = corner;
      }
    }
  });
  tbb::enumerable_thread_specific<VertexScratch> vertex_scratches;
  Counts counts = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, nshared, 1 << 12), Counts{},
      [&](const tbb::blocked_range<std::size_t>& r, Counts sum) {
        VertexScratch& vs = vertex_scratches.local();
        for (std::size_t k = r.begin(); k < r.end(); ++k) {
          const C first = k == 0 ? C{0} : shared_bound[k - 1].load(std::memory_order_relaxed);
          const C last = shared_bound[k].load(std::memory_order_relaxed);
          const C* at = shared_incident.get() + first;
          const std::uint32_t v = shared_vertex[k];
          const auto degree = static_cast<std::size_t>(last - first);
          Side sides[kFastDegree + kSideSlack] = {};
          for (std::size_t j = 0; j < std::min(degree, kFastDegree); ++j) {
            sides[j] = side_of(at[j], corners);
          }
          examine(
              v, degree, [&](std::size_t j) { return at[j]; }, sides, corners, ctx, vs, sum);
        }
        return sum;
      },
      [](Counts a, const Counts& b) { return a += b; });

  // Components: those of the chunks that reach no shared vertex, plus the classes of the shared
  // vertices under the chunks' links.
  ConcurrentUnionFind shared_components(nshared);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nchunks, 1), [&](const auto& r) {
    for (std::size_t c = r.begin(); c < r.end(); ++c) {
      for (const auto& [a, b] : results[c].shared_links) shared_components.unite(a, b);
    }
  });
  for (std::size_t k = 0; k < nshared; ++k) counts.components += shared_components.is_root(k);
  for (const auto& r : results) counts += r.counts;

  TopologyStats s;
  s.vertices = counts.vertices;
  s.unreferenced_vertices = unreferenced;
  s.edges = counts.edges;
  s.faces = nfaces;
  s.boundary_edges = counts.boundary;
  s.border_boundary_edges = counts.border;
  s.nonmanifold_edges = counts.nonmanifold_edges;
  s.nonmanifold_vertices = counts.nonmanifold_vertices;
  s.inconsistently_oriented_edges = counts.inconsistent;
  s.euler = static_cast<std::int64_t>(s.vertices) - static_cast<std::int64_t>(s.edges) +
            static_cast<std::int64_t>(s.faces);
  s.components = counts.components;
  s.closed = s.boundary_edges == 0 && s.nonmanifold_edges == 0;
  s.watertight = s.boundary_edges == s.border_boundary_edges && s.nonmanifold_edges == 0;
  return s;
}

template <class C>
TopologyStats compute_with_corners(const Mesh& mesh, const TopologyOptions& options) {
  // One word of state a vertex: 32 bits whenever the vertex numbers leave room for the flags.
  if (mesh.positions.size() < (std::size_t{1} << 30)) {
    return compute<C, std::uint32_t>(mesh, options);
  }
  return compute<C, std::uint64_t>(mesh, options);
}

}  // namespace

TopologyStats mesh_topology(const Mesh& mesh, const TopologyOptions& options) {
  check_face_indices(mesh);
  const std::uint64_t corners =
      3 * std::uint64_t{mesh.triangles.size()} + 4 * std::uint64_t{mesh.quads.size()};
  // 32-bit corner numbers whenever they suffice.
  if (corners < std::numeric_limits<std::uint32_t>::max()) {
    return compute_with_corners<std::uint32_t>(mesh, options);
  }
  return compute_with_corners<std::uint64_t>(mesh, options);
}

}  // namespace isotile
