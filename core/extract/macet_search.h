// Macet's Max mode: a local search per grid vertex that raises the worst triangles around it.
// Internal to core/.
//
// Moving grid vertex v changes only the crossings on its own (up to six) crossed edges, and those
// only appear in triangles of the eight cells around v (its moving triangles). For every grid
// vertex whose moving triangles include one worse than the goal, the search tries displacements
// around the current one (26 directions at a few radii, then a finer round around the best) and
// keeps the one that raises their minimum radius ratio, subject to
//   * the vertex keeps its side of the surface (so every edge still brackets a crossing and the
//     topology stays MC's),
//   * it stays within max_move voxels of its grid position,
//   * no moving triangle turns over (its normal keeps a positive dot product with the current one),
//   * every moving triangle lies strictly inside v's box, the cube of half-width 1.5 samples
//     around v, before and after the move, and
//   * the moving triangles intersect each other and every other triangle of the mesh in no more
//     pairs than before (the rule of core/mesh/self_intersections.h, exactly: on the float world
//     coordinates that are emitted, vertices identified by position as it does).
// The guard is complete: a triangle of cell o lies within [o - 1, o + 2] samples along each axis
// (its corners are crossings between grid vertices displaced by at most one voxel), so only the
// cells o in [v - 3, v + 2] can reach v's box, and the guard tests all their triangles that meet
// it. A move therefore never raises the mesh's count of intersecting pairs.
//
// Determinism and parallelism: vertices are swept in 27 colours by their GLOBAL coordinates modulo
// 3. Two vertices of one colour lie at least three samples apart along some axis, so their boxes
// are disjoint: neither's moving triangles can meet the other's, whatever either does, and neither
// reads a crossing of its eight cells that the other changes. Each colour step first finds every
// vertex's move from the same state (nothing is written), then applies them all: the result equals
// visiting the colour's vertices one after another in any order, and is the same for any thread
// count and any brick cut. Crossings are stored per crossed edge and updated when an end point
// moves, so the guard and the fixed corners read them without a root search.
// macet_search_reach() bounds how far the steps can carry a change (macet_halo).
#pragma once

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/extract/inside_bits.h"
#include "core/extract/macet_field.h"
#include "core/extract/macet_table.h"
#include "core/extract/marching_cubes_tables.h"
#include "core/mesh/self_intersections.h"
#include "core/progress.h"

namespace isotile::detail {

struct MacetSearchParams {
  double goal = 0.6;  // vertices whose affected triangles are all at least this good stay
  // Voxels from the grid position. 1.0 rather than 0.6 frees the neighbours of grid vertices
  // pinned by their sign in one-voxel-thin features (bonsai's minimum 0.088 -> 0.107); the
  // intersection guard keeps the longer moves from folding sheets into each other.
  double max_move = 1.0;
};

inline double radius_ratio_d(const P3& a, const P3& b, const P3& c) {
  auto dist = [](const P3& p, const P3& q) {
    const double x = p[0] - q[0], y = p[1] - q[1], z = p[2] - q[2];
    return std::sqrt(x * x + y * y + z * z);
  };
  const double la = dist(b, c), lb = dist(c, a), lc = dist(a, b);
  const double den = la * lb * lc;
  if (den <= 0) return 0;
  return std::max(0.0, (lb + lc - la) * (lc + la - lb) * (la + lb - lc) / den);
}

inline P3 tri_normal(const P3& a, const P3& b, const P3& c) {
  const P3 u{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v{c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  return {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
}

// Colours of the search: global coordinates modulo kColourSpacing along each axis, visited in this
// order: residues summing to 0, 1, 2 (mod 3) in turn, so that few consecutive colours share a
// residue along one axis. With x fastest, a chain of steps could climb three samples per step
// along z (74 per sweep against 42 in this order; see macet_search_reach).
inline constexpr int kColourSpacing = 3;
inline constexpr int kSearchColours = kColourSpacing * kColourSpacing * kColourSpacing;
inline constexpr int kColourOrder[kSearchColours][3] = {
    {0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {0, 2, 1}, {1, 0, 2}, {2, 1, 0}, {0, 1, 2},
    {1, 2, 0}, {2, 0, 1}, {0, 0, 1}, {1, 1, 2}, {2, 2, 0}, {0, 2, 2}, {1, 0, 0},
    {2, 1, 1}, {0, 1, 0}, {1, 2, 1}, {2, 0, 2}, {0, 0, 2}, {1, 1, 0}, {2, 2, 1},
    {0, 2, 0}, {1, 0, 1}, {2, 1, 2}, {0, 1, 1}, {1, 2, 2}, {2, 0, 0}};
// Half-width of a vertex's box in samples: half the colour spacing, so that the boxes of two
// vertices of one colour are disjoint open cubes.
inline constexpr double kBoxHalf = 0.5 * kColourSpacing;
// Cells whose triangles can reach v's box: o in [v - kGuardReach, v + kGuardReach - 1] (a triangle
// of cell o lies within [o - 1, o + 2]); a colour step at v reads the displacements of the grid
// vertices within kGuardReach of v.
inline constexpr int kGuardReach = 3;

// How far (in samples, along one axis) a change can travel in `sweeps` sweeps: the longest chain
// of grid vertices visited at strictly increasing colour steps in which each reads the one before
// (within kGuardReach along each axis, so a hop between colours whose residues differ by d along
// the axis covers at most the largest value in [-kGuardReach, kGuardReach] congruent to d).
inline int macet_search_reach(int sweeps) {
  const int steps = std::max(sweeps, 0) * kSearchColours;
  auto hop = [](int from, int to, int axis) {
    const int d =
        ((kColourOrder[to][axis] - kColourOrder[from][axis]) % kColourSpacing + kColourSpacing) %
        kColourSpacing;
    int best = -kGuardReach - 1;
    for (int x = -kGuardReach; x <= kGuardReach; ++x)
      if (((x - d) % kColourSpacing + kColourSpacing) % kColourSpacing == 0) best = x;
    return best;
  };
  int reach = 0;
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<int> best(static_cast<std::size_t>(steps), 0);
    for (int t = 0; t < steps; ++t) {
      for (int u = 0; u < t; ++u)
        best[t] = std::max(best[t], best[u] + hop(u % kSearchColours, t % kSearchColours, axis));
      reach = std::max(reach, best[t]);
    }
  }
  return reach;
}

// The guard's filter before the exact predicates: a triangle's plane in doubles, and whether a
// pair certainly does not intersect under the rule of core/mesh/self_intersections.h.
struct GuardPlane {
  P3 n, n_abs;  // (p1 - p0) x (p2 - p0) in doubles; n_abs: the same with |products| added
};

// `certain_area`: the projection onto some axis plane certainly has area (Shewchuk's orient2d
// bound (3 + 16 eps) eps, eps = 2^-53, with margin), so the triangle has.
inline GuardPlane guard_plane(const std::array<Vec3f, 3>& p, bool& certain_area) {
  GuardPlane g;
  double u[3], w[3];
  for (int k = 0; k < 3; ++k) {
    u[k] = double(p[1][k]) - double(p[0][k]);
    w[k] = double(p[2][k]) - double(p[0][k]);
  }
  certain_area = false;
  for (int k = 0; k < 3; ++k) {
    const int k1 = (k + 1) % 3, k2 = (k + 2) % 3;
    const double x = u[k1] * w[k2], y = u[k2] * w[k1];
    g.n[k] = x - y;
    g.n_abs[k] = std::abs(x) + std::abs(y);
    certain_area = certain_area || std::abs(g.n[k]) > 4e-16 * g.n_abs[k];
  }
  return g;
}

// The side of point x of the plane of triangle p: +1 or -1 when certain, 0 when the double
// arithmetic cannot tell (Shewchuk's orient3d bound (7 + 56 eps) eps, with margin, on the same
// products: the differences to p's first corner, then the cofactors).
inline int guard_side(const std::array<Vec3f, 3>& p, const GuardPlane& g, const Vec3f& x) {
  double det = 0, perm = 0;
  for (int k = 0; k < 3; ++k) {
    const double d = double(x[k]) - double(p[0][k]);
    det += d * g.n[k];
    perm += std::abs(d) * g.n_abs[k];
  }
  if (perm < 1e-250) return 0;  // near underflow the relative bound does not hold
  const double bound = 1e-15 * perm;
  return det > bound ? 1 : det < -bound ? -1 : 0;
}

// True when the corners of b that a does not share (shared_with_a[l] >= 0: b's corner l is one
// of a's) all lie certainly strictly on one side of a's plane: then b meets a's plane only in the
// shared corners, and the pair does not intersect (with no corner shared there is no common
// point, with one none but it, with two the triangles are not coplanar). False says nothing.
inline bool guard_apart(const std::array<Vec3f, 3>& a, const GuardPlane& ga,
                        const std::array<Vec3f, 3>& b, const int shared_with_a[3]) {
  int first = 0;
  for (int l = 0; l < 3; ++l) {
    if (shared_with_a[l] >= 0) continue;
    const int sd = guard_side(a, ga, b[l]);
    if (sd == 0 || (first != 0 && sd != first)) return false;
    first = sd;
  }
  return first != 0;
}

template <class T>
class LocalSearch {
 public:
  // `progress`: advanced per row of grid vertices in every pass over them (see
  // macet_local_search), a z-slice at a time.
  LocalSearch(const Field<T>& field, const BitGrid& grid, GridVertices& gv,
              const MacetCaseTable& table, MacetSearchParams params, Progress* progress = nullptr)
      : field_(field), grid_(grid), gv_(gv), table_(table), params_(params), progress_(progress) {
    // 26 unit directions.
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (!dx && !dy && !dz) continue;
          const double n = std::sqrt(double(dx * dx + dy * dy + dz * dz));
          dirs_.push_back({dx / n, dy / n, dz / n});
        }
    const std::size_t nv = gv_.disp.size();
    last_moved_.assign(nv, -1);
    settled_at_.assign(nv, -1);
    settled_reach_.assign(nv, 1);
    // The crossing store: slot xoff_[v] + rank of the axis among v's crossed +axis edges.
    xoff_.resize(nv + 1);
    xoff_[0] = 0;
    for_vertices(-1, [&](std::int64_t i, std::int64_t j, std::int64_t k, std::uint32_t idx) {
      const std::int64_t s[3] = {i, j, k};
      xoff_[idx + 1] = crossed(s, 0) + crossed(s, 1) + crossed(s, 2);
    });
    for (std::size_t n = 0; n < nv; ++n) xoff_[n + 1] += xoff_[n];
    xpos_.resize(xoff_[nv]);
    for_vertices(-1, [&](std::int64_t i, std::int64_t j, std::int64_t k, std::uint32_t) {
      const std::int64_t s[3] = {i, j, k};
      for (int a = 0; a < 3; ++a)
        if (crossed(s, a)) xpos_[slot(s, a)] = crossing(s, a, ~0u, P3{}, 0);
    });
  }

  void sweep() {
    for (int colour = 0; colour < kSearchColours; ++colour) {
      colour_step(colour);
      ++step_;
    }
  }

 private:
  struct Proposal {
    std::uint32_t index;
    std::int64_t v[3];
    P3 d;
    double f;
  };

  bool inside(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return (grid_.row(j, k)[i >> 6] >> (i & 63)) & 1;
  }

  // Whether the edge from local sample s along +a is crossed.
  bool crossed(const std::int64_t s[3], int a) const {
    std::int64_t q[3] = {s[0], s[1], s[2]};
    if (++q[a] >= field_.view.dims[a]) return false;
    return inside(s[0], s[1], s[2]) != inside(q[0], q[1], q[2]);
  }

  // The store slot of crossed edge (s, +a); s is a grid vertex.
  std::uint32_t slot(const std::int64_t s[3], int a) const {
    std::uint32_t r = xoff_[gv_.index(s[0], s[1], s[2])];
    for (int c = 0; c < a; ++c) r += crossed(s, c);
    return r;
  }

  // Calls fn(i, j, k, index) for every grid vertex of colour `colour` (-1: all), rows in
  // parallel.
  template <class F>
  void for_vertices(int colour, F&& fn) const {
    const Box3& b = gv_.box;
    const VolumeView& view = field_.view;
    const int cx = colour >= 0 ? kColourOrder[colour][0] : 0,
              cy = colour >= 0 ? kColourOrder[colour][1] : 0,
              cz = colour >= 0 ? kColourOrder[colour][2] : 0;
    auto residue = [](std::int64_t x) { return static_cast<int>(x % kColourSpacing); };
    // Bits b with b % 3 == r.
    std::uint64_t every_third[kColourSpacing] = {};
    for (int bit = 0; bit < 64; ++bit) every_third[bit % kColourSpacing] |= std::uint64_t{1} << bit;
    const std::int64_t rows = b.extent(1) * b.extent(2);
    auto body = [&](const auto& range) {
      for (std::int64_t r = range.begin(); r != range.end(); ++r) {
        const std::int64_t j = b.lo[1] + r % gv_.ny, k = b.lo[2] + r / gv_.ny;
        if (colour >= 0 && (residue(view.box.lo[1] + j) != cy || residue(view.box.lo[2] + k) != cz))
          continue;
        for (std::int64_t w = b.lo[0] >> 6; w <= (b.hi[0] - 1) >> 6; ++w) {
          const std::size_t word = static_cast<std::size_t>(r * gv_.words + w);
          std::uint64_t m = gv_.bits[word];
          if (colour >= 0) {
            // Local x = 64 w + bit has the colour's residue when bit = cx - lo - 64 w (mod 3).
            const std::int64_t want = cx - view.box.lo[0] - 64 * w;
            m &= every_third[residue(want % kColourSpacing + kColourSpacing)];
          }
          for (; m; m &= m - 1) {
            const int bit = std::countr_zero(m);
            const std::uint64_t below = (std::uint64_t{1} << bit) - 1;
            fn(w * 64 + bit, j, k,
               gv_.prefix[word] +
                   static_cast<std::uint32_t>(std::popcount(gv_.bits[word] & below)));
          }
        }
      }
    };
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, rows),
                      for_units(progress_, gv_.ny, body));
  }

  void colour_step(int colour) {
    // Every move of the colour is found from the same state, then all are applied (see the top
    // of this file: they cannot interact).
    for (auto& list : proposals_) list.clear();
    for_vertices(colour, [&](std::int64_t i, std::int64_t j, std::int64_t k, std::uint32_t idx) {
      Proposal p;
      if (improve(i, j, k, idx, p)) proposals_.local().push_back(p);
    });
    for (auto& list : proposals_) {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, list.size()), [&](const auto& range) {
        for (std::size_t n = range.begin(); n != range.end(); ++n) apply(list[n]);
      });
    }
  }

  // Moves a vertex and updates the crossings on its edges (their other ends have other colours).
  void apply(const Proposal& p) {
    gv_.disp[p.index] = p.d;
    gv_.value[p.index] = p.f;
    last_moved_[p.index] = step_;
    for (int a = 0; a < 3; ++a) {
      if (crossed(p.v, a)) xpos_[slot(p.v, a)] = crossing(p.v, a, ~0u, P3{}, 0);
      std::int64_t s[3] = {p.v[0], p.v[1], p.v[2]};
      if (--s[a] >= 0 && crossed(s, a)) xpos_[slot(s, a)] = crossing(s, a, ~0u, P3{}, 0);
    }
  }

  // The crossing on edge (s, axis a) with the current displacements, except that grid vertex
  // `moved` uses (d, f) instead. The emission computes the same (same inputs, same arithmetic).
  // `cache`: find_root's cell samples, kept per edge across a vertex's candidates.
  P3 crossing(const std::int64_t s[3], int a, std::uint32_t moved, const P3& d, double f,
              typename Field<T>::Corners* cache = nullptr) const {
    std::int64_t q[3] = {s[0], s[1], s[2]};
    ++q[a];
    const std::uint32_t i0 = gv_.index(s[0], s[1], s[2]), i1 = gv_.index(q[0], q[1], q[2]);
    const P3& d0 = i0 == moved ? d : gv_.disp[i0];
    const P3& d1 = i1 == moved ? d : gv_.disp[i1];
    const double f0 = i0 == moved ? f : gv_.value[i0], f1 = i1 == moved ? f : gv_.value[i1];
    const P3 p0 = field_.global(s[0], s[1], s[2], d0);
    const P3 p1 = field_.global(q[0], q[1], q[2], d1);
    const bool straight = d0 == P3{0, 0, 0} && d1 == P3{0, 0, 0};
    const double t = edge_crossing(field_, grid_, s, q, p0, p1, f0, f1, straight, cache);
    return {p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]), p0[2] + t * (p1[2] - p0[2])};
  }

  int cell_case(const std::int64_t o[3]) const {
    int cs = 0;
    for (int corner = 0; corner < 8; ++corner)
      cs |= int(inside(o[0] + (corner & 1), o[1] + ((corner >> 1) & 1), o[2] + ((corner >> 2) & 1)))
            << corner;
    return cs;
  }

  // Whether a grid vertex within `reach` of v (along each axis) moved at or after `step`.
  bool moved_since(const std::int64_t v[3], int reach, int step) const {
    for (int dz = -reach; dz <= reach; ++dz)
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dx = -reach; dx <= reach; ++dx) {
          const std::int64_t q[3] = {v[0] + dx, v[1] + dy, v[2] + dz};
          if (gv_.contains(q[0], q[1], q[2]) && last_moved_[gv_.index(q[0], q[1], q[2])] >= step)
            return true;
        }
    return false;
  }

  // A triangle as the intersection test sees it: emitted float world coordinates, with its plane
  // for the filter in meet().
  struct Corners {
    std::array<Vec3f, 3> p;
    Vec3f lo, hi;
    bool live;
    GuardPlane plane;
  };

  Vec3f world(const P3& x) const {
    const VolumeView& view = field_.view;
    Vec3f w;
    for (int c = 0; c < 3; ++c) w[c] = static_cast<float>(view.origin[c] + view.spacing[c] * x[c]);
    return w;
  }

  // A triangle's corners and bounding box; finish() adds what only the pair test needs, so that
  // triangles the box tests drop never pay for it.
  Corners bound_corners(const P3& a, const P3& b, const P3& c) const {
    Corners t;
    t.p = {world(a), world(b), world(c)};
    for (int k = 0; k < 3; ++k) {
      t.lo[k] = std::min({t.p[0][k], t.p[1][k], t.p[2][k]});
      t.hi[k] = std::max({t.p[0][k], t.p[1][k], t.p[2][k]});
    }
    return t;
  }

  static void finish(Corners& t) {
    bool certain_area = false;
    t.plane = guard_plane(t.p, certain_area);
    t.live = certain_area || triangle_has_area(t.p);
  }

  // self_intersections' rule for one pair, vertices identified by position as it does. The
  // plane filter settles most pairs in doubles; the rest go to the exact predicates.
  static bool meet(const Corners& a, const Corners& b) {
    for (int k = 0; k < 3; ++k)
      if (a.hi[k] < b.lo[k] || b.hi[k] < a.lo[k]) return false;
    if (!a.live || !b.live) return false;
    const std::array<std::uint32_t, 3> ia{0, 1, 2};
    std::array<std::uint32_t, 3> ib{3, 4, 5};
    int b_in_a[3] = {-1, -1, -1}, a_in_b[3] = {-1, -1, -1};
    for (int l = 0; l < 3; ++l)
      for (std::uint32_t k = 0; k < 3; ++k)
        if (b.p[l] == a.p[k]) {
          ib[l] = k;
          b_in_a[l] = static_cast<int>(k);
          a_in_b[k] = l;
        }
    if (guard_apart(a.p, a.plane, b.p, b_in_a) || guard_apart(b.p, b.plane, a.p, a_in_b))
      return false;
    return triangles_intersect(a.p, ia, b.p, ib);
  }

  void settle(std::uint32_t self, int reach) {
    settled_at_[self] = step_;
    settled_reach_[self] = static_cast<std::int8_t>(reach);
  }

  // Finds the move of grid vertex (i, j, k) (dense index `self`); true with `out` filled when it
  // moves.
  bool improve(std::int64_t i, std::int64_t j, std::int64_t k, std::uint32_t self, Proposal& out) {
    const VolumeView& view = field_.view;
    const std::int64_t v[3] = {i, j, k};
    // A vertex whose last visit left it in place without consulting the guard (its triangles
    // good enough, or no candidate better) would do the same again until a vertex of its 3x3x3
    // block moves (its eight cells' crossings depend on that block only); one that the guard or
    // its box kept in place, until a vertex within kGuardReach moves (the guard reads no further).
    // Skipping it until then gives exactly what a visit would. Moves are applied after the step,
    // so nothing read here changes during it.
    if (settled_at_[self] >= 0 && !moved_since(v, settled_reach_[self], settled_at_[self]))
      return false;
    settled_at_[self] = -1;
    const bool in = inside(i, j, k);

    // The moving triangles: those of the eight cells around v that use a crossing on one of v's
    // edges. Crossings are slots: fixed ones read from the store, moving ones per candidate.
    struct Slot {
      std::int64_t s[3];
      int axis;
    };
    std::array<Slot, 6> moving{};
    int n_moving = 0;
    std::array<P3, 8 * 12> fixed{};
    int n_fixed = 0;
    struct TriRef {
      std::int16_t v[3];  // >= 0: fixed slot; < 0: moving slot -1 - m
    };
    std::array<TriRef, 8 * mc::kMaxTrianglesPerCase> tris{};
    int n_tris = 0;
    // The other triangles of the eight cells (all corners fixed), for the intersection guard.
    std::array<TriRef, 8 * mc::kMaxTrianglesPerCase> statics{};
    int n_statics = 0;

    for (int c = 0; c < 8; ++c) {
      std::int64_t o[3];
      bool ok = true;
      for (int a = 0; a < 3; ++a) {
        o[a] = v[a] - 1 + ((c >> a) & 1);
        ok = ok && o[a] >= 0 && o[a] + 1 < view.dims[a];
      }
      if (!ok) continue;
      const int cs = cell_case(o);
      const int nt = table_.triangle_count[cs];
      if (nt == 0) continue;
      std::int16_t slot_of[12];
      for (unsigned em = table_.edge_mask[cs]; em; em &= em - 1) {
        const int e = std::countr_zero(em);
        const int c0 = mc::kEdgeCorners[e][0];
        const std::int64_t s[3] = {o[0] + (c0 & 1), o[1] + ((c0 >> 1) & 1), o[2] + ((c0 >> 2) & 1)};
        const int a = e / 4;
        std::int64_t q[3] = {s[0], s[1], s[2]};
        ++q[a];
        const bool touches = (s[0] == v[0] && s[1] == v[1] && s[2] == v[2]) ||
                             (q[0] == v[0] && q[1] == v[1] && q[2] == v[2]);
        if (touches) {
          int m = 0;
          while (m < n_moving && !(moving[m].axis == a && moving[m].s[0] == s[0] &&
                                   moving[m].s[1] == s[1] && moving[m].s[2] == s[2]))
            ++m;
          if (m == n_moving) moving[n_moving++] = {{s[0], s[1], s[2]}, a};
          slot_of[e] = static_cast<std::int16_t>(-1 - m);
        } else {
          slot_of[e] = static_cast<std::int16_t>(n_fixed);
          fixed[n_fixed++] = xpos_[slot(s, a)];
        }
      }
      const auto& tt = table_.triangles[cs];
      for (int t = 0; t < nt; ++t) {
        const TriRef ref{{slot_of[tt[3 * t]], slot_of[tt[3 * t + 1]], slot_of[tt[3 * t + 2]]}};
        if (ref.v[0] < 0 || ref.v[1] < 0 || ref.v[2] < 0)
          tris[n_tris++] = ref;
        else
          statics[n_statics++] = ref;
      }
    }
    if (n_tris == 0) {
      settle(self, 1);
      return false;
    }

    // Moving crossings for the candidate (cand_d, cand_f), computed when first needed: most
    // candidates are rejected after a crossing or two (see score).
    std::array<P3, 6> mpos{};
    std::array<typename Field<T>::Corners, 6> samples;  // per moving edge, for find_root
    // What a candidate does not change on a moving edge: its other end (crossing() for the
    // candidate is then these with v's end replaced; same inputs, same arithmetic).
    struct OtherEnd {
      std::int64_t q[3];  // the edge's other end point
      bool v_first;       // v is the edge's lower end
      P3 p, d;            // its displaced position and displacement
      double f;
    };
    std::array<OtherEnd, 6> other_end;
    for (int m = 0; m < n_moving; ++m) {
      OtherEnd& e = other_end[m];
      e.v_first = moving[m].s[0] == v[0] && moving[m].s[1] == v[1] && moving[m].s[2] == v[2];
      for (int a = 0; a < 3; ++a) e.q[a] = moving[m].s[a];
      if (e.v_first) ++e.q[moving[m].axis];
      const std::uint32_t iq = gv_.index(e.q[0], e.q[1], e.q[2]);
      e.d = gv_.disp[iq];
      e.f = gv_.value[iq];
      e.p = field_.global(e.q[0], e.q[1], e.q[2], e.d);
    }
    auto moving_crossing = [&](int m, const P3& d, double f) {
      const OtherEnd& e = other_end[m];
      const P3 pv = field_.global(v[0], v[1], v[2], d);
      const bool straight = d == P3{0, 0, 0} && e.d == P3{0, 0, 0};
      const P3& p0 = e.v_first ? pv : e.p;
      const P3& p1 = e.v_first ? e.p : pv;
      const double t =
          e.v_first ? edge_crossing(field_, grid_, v, e.q, p0, p1, f, e.f, straight, &samples[m])
                    : edge_crossing(field_, grid_, e.q, v, p0, p1, e.f, f, straight, &samples[m]);
      return P3{p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]),
                p0[2] + t * (p1[2] - p0[2])};
    };
    P3 cand_d{};
    double cand_f = 0;
    unsigned placed = 0;  // bit m: mpos[m] holds the candidate's crossing
    auto stage = [&](const P3& d, double f) {
      cand_d = d;
      cand_f = f;
      placed = 0;
    };
    auto place = [&](const P3& d, double f) {
      stage(d, f);
      for (int m = 0; m < n_moving; ++m) mpos[m] = moving_crossing(m, d, f);
      placed = (1u << n_moving) - 1;
    };
    auto place_current = [&]() {
      stage(gv_.disp[self], gv_.value[self]);
      for (int m = 0; m < n_moving; ++m) mpos[m] = xpos_[slot(moving[m].s, moving[m].axis)];
      placed = (1u << n_moving) - 1;
    };
    auto pos = [&](std::int16_t s) -> const P3& {
      if (s >= 0) return fixed[s];
      const int m = -1 - s;
      if (!((placed >> m) & 1)) {
        mpos[m] = moving_crossing(m, cand_d, cand_f);
        placed |= 1u << m;
      }
      return mpos[m];
    };
    std::array<P3, 8 * mc::kMaxTrianglesPerCase> normal0{};
    std::array<double, 8 * mc::kMaxTrianglesPerCase> q0{};
    std::array<int, 8 * mc::kMaxTrianglesPerCase> order{};
    for (int t = 0; t < n_tris; ++t) order[t] = t;
    // The minimum radius ratio of the moving triangles, -1 when one turns over, and with a
    // `bar`, -1 as soon as one is no better than it: such a candidate can never be chosen, and
    // visiting the worst triangles first stops most candidates early.
    auto score = [&](bool record, double bar = -1.0) {
      double worst = 1.0;
      for (int o = 0; o < n_tris; ++o) {
        const int t = order[o];
        const P3 &a = pos(tris[t].v[0]), &b = pos(tris[t].v[1]), &c = pos(tris[t].v[2]);
        if (record) {
          normal0[t] = tri_normal(a, b, c);
        } else {
          const P3 n = tri_normal(a, b, c);
          const P3& n0 = normal0[t];
          const double len0 = n0[0] * n0[0] + n0[1] * n0[1] + n0[2] * n0[2];
          if (len0 > 1e-20 && n[0] * n0[0] + n[1] * n0[1] + n[2] * n0[2] <= 0) return -1.0;
        }
        const double q = radius_ratio_d(a, b, c);
        if (record) q0[t] = q;
        if (q <= bar) return -1.0;
        worst = std::min(worst, q);
      }
      return worst;
    };

    // v's box in world floats (rounding is monotone, so a point strictly inside it in floats lies
    // strictly inside the open cube in samples' terms, up to rounding shared by both sides).
    Vec3f box_lo, box_hi;
    for (int a = 0; a < 3; ++a) {
      const double g = static_cast<double>(view.box.lo[a] + v[a]);
      const float x0 = static_cast<float>(view.origin[a] + view.spacing[a] * (g - kBoxHalf));
      const float x1 = static_cast<float>(view.origin[a] + view.spacing[a] * (g + kBoxHalf));
      box_lo[a] = std::min(x0, x1);
      box_hi[a] = std::max(x0, x1);
    }
    auto in_box = [&](const Corners& t) {
      for (int a = 0; a < 3; ++a)
        if (!(t.lo[a] > box_lo[a] && t.hi[a] < box_hi[a])) return false;
      return true;
    };
    auto meets_box = [&](const Corners& t) {
      for (int a = 0; a < 3; ++a)
        if (t.hi[a] < box_lo[a] || t.lo[a] > box_hi[a]) return false;
      return true;
    };

    // The guard's other triangles: the eight cells' fixed ones and those of the cells within
    // kGuardReach that meet v's box (built on the first candidate that needs the guard: most
    // vertices never get that far).
    static thread_local std::vector<Corners> others;
    others.clear();
    auto build_ring = [&]() {
      for (int t = 0; t < n_statics; ++t) {
        Corners c = bound_corners(pos(statics[t].v[0]), pos(statics[t].v[1]), pos(statics[t].v[2]));
        if (!meets_box(c)) continue;
        finish(c);
        others.push_back(c);
      }
      for (std::int64_t dz = -kGuardReach; dz < kGuardReach; ++dz)
        for (std::int64_t dy = -kGuardReach; dy < kGuardReach; ++dy)
          for (std::int64_t dx = -kGuardReach; dx < kGuardReach; ++dx) {
            if (dx >= -1 && dx <= 0 && dy >= -1 && dy <= 0 && dz >= -1 && dz <= 0)
              continue;  // one of the eight cells
            const std::int64_t d[3] = {dx, dy, dz};
            std::int64_t o[3];
            bool ok = true;
            for (int a = 0; a < 3; ++a) {
              o[a] = v[a] + d[a];
              ok = ok && o[a] >= 0 && o[a] + 1 < view.dims[a];
            }
            if (!ok) continue;
            const int cs = cell_case(o);
            const int nt = table_.triangle_count[cs];
            if (nt == 0) continue;
            P3 x[12];
            for (unsigned em = table_.edge_mask[cs]; em; em &= em - 1) {
              const int e = std::countr_zero(em);
              const int c0 = mc::kEdgeCorners[e][0];
              const std::int64_t s[3] = {o[0] + (c0 & 1), o[1] + ((c0 >> 1) & 1),
                                         o[2] + ((c0 >> 2) & 1)};
              x[e] = xpos_[slot(s, e / 4)];
            }
            const auto& tt = table_.triangles[cs];
            for (int t = 0; t < nt; ++t) {
              Corners c = bound_corners(x[tt[3 * t]], x[tt[3 * t + 1]], x[tt[3 * t + 2]]);
              if (!meets_box(c)) continue;
              finish(c);
              others.push_back(c);
            }
          }
    };
    std::array<Corners, 8 * mc::kMaxTrianglesPerCase> moving_corners;
    static thread_local std::vector<const Corners*> near;
    // The moving triangles as placed, and their common bounding box: false when one leaves v's
    // box.
    Vec3f moving_lo{}, moving_hi{};
    auto place_moving_corners = [&]() {
      for (int t = 0; t < n_tris; ++t) {
        Corners& m = moving_corners[t];
        m = bound_corners(pos(tris[t].v[0]), pos(tris[t].v[1]), pos(tris[t].v[2]));
        if (!in_box(m)) return false;
        for (int a = 0; a < 3; ++a) {
          moving_lo[a] = t == 0 ? m.lo[a] : std::min(moving_lo[a], m.lo[a]);
          moving_hi[a] = t == 0 ? m.hi[a] : std::max(moving_hi[a], m.hi[a]);
        }
      }
      for (int t = 0; t < n_tris; ++t) finish(moving_corners[t]);
      return true;
    };
    // Their intersecting pairs, once placed. Only the other triangles that meet the moving ones'
    // common bounding box can take part in a pair.
    auto intersecting_pairs = [&]() {
      near.clear();
      for (const Corners& u : others) {
        bool apart_boxes = false;
        for (int a = 0; a < 3; ++a)
          apart_boxes = apart_boxes || u.hi[a] < moving_lo[a] || moving_hi[a] < u.lo[a];
        if (!apart_boxes) near.push_back(&u);
      }
      int n = 0;
      for (int t = 0; t < n_tris; ++t) {
        if (!moving_corners[t].live) continue;
        for (const Corners* u : near) n += meet(moving_corners[t], *u);
        for (int u = 0; u < t; ++u) n += meet(moving_corners[t], moving_corners[u]);
      }
      return n;
    };

    P3 best_d = gv_.disp[self];
    double best_f = gv_.value[self];
    place_current();
    double best = score(true);
    if (best >= params_.goal) {
      settle(self, 1);
      return false;
    }
    std::stable_sort(order.begin(), order.begin() + n_tris,
                     [&](int x, int y) { return q0[x] < q0[y]; });
    const double start = best;
    // The guard's state, set up on the first candidate that needs it: whether the current
    // moving triangles lie in v's box (if not, no candidate can pass, and the ring is not built),
    // and their pair count, needed only once a candidate has pairs.
    bool guard_ready = false, start_in_box = true;
    int allowed_pairs = -1;
    auto with_current = [&](auto&& fn) {  // fn() on the current position, then the candidate back
      const std::array<P3, 6> kept = mpos;
      const P3 kept_d = cand_d;
      const double kept_f = cand_f;
      const unsigned kept_placed = placed;
      place_current();
      fn();
      mpos = kept;
      cand_d = kept_d;
      cand_f = kept_f;
      placed = kept_placed;
    };
    // Called with a candidate placed; leaves it placed.
    auto guard_passes = [&]() {
      if (!guard_ready) {
        guard_ready = true;
        with_current([&] { start_in_box = place_moving_corners(); });
        if (start_in_box) build_ring();
      }
      if (!start_in_box || !place_moving_corners()) return false;
      const int n = intersecting_pairs();
      if (n == 0) return true;
      if (allowed_pairs < 0)
        with_current([&] {
          place_moving_corners();
          allowed_pairs = intersecting_pairs();
        });
      return n <= allowed_pairs;
    };

    // A round keeps the best-scoring candidate that passes the guard (the first in scan order
    // among equal scores). The guard is the costly test, so it runs only on the round's best
    // candidate; a scan raises its bar to the best score so far (a candidate no better than it can
    // no longer win, and its worst triangles usually say so at once). When the guard refuses the
    // winner, the scan runs again without it: that finds the next candidate in the order (score
    // descending, then scan order), as sorting all candidates would.
    struct Candidate {
      P3 d;
      double f;
    };
    std::array<Candidate, 26 * 4> candidates;
    std::array<bool, 26 * 4> refused;
    bool any_candidate = false;
    typename Field<T>::Corners candidate_cell;  // neighbouring candidates share cells
    auto try_round = [&](const P3& centre, std::initializer_list<double> radii) {
      int n = 0;
      for (double r : radii)
        for (const P3& dir : dirs_) {
          P3 d{centre[0] + r * dir[0], centre[1] + r * dir[1], centre[2] + r * dir[2]};
          const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
          if (len > params_.max_move) continue;
          const P3 p = field_.displaced(v, d);
          const P3 g = field_.global(v[0], v[1], v[2]);
          for (int a = 0; a < 3; ++a) d[a] = p[a] - g[a];
          const double f = field_.value(p, candidate_cell);
          if ((f >= 0) != in) continue;
          refused[n] = false;
          candidates[n++] = {d, f};
        }
      for (;;) {
        double bar = best;
        int winner = -1;
        for (int c = 0; c < n; ++c) {
          if (refused[c]) continue;
          stage(candidates[c].d, candidates[c].f);
          const double sc = score(false, bar);
          if (sc > bar) {
            bar = sc;
            winner = c;
          }
        }
        if (winner < 0) return;
        any_candidate = true;
        const Candidate& w = candidates[winner];
        place(w.d, w.f);
        if (guard_passes()) {
          best = bar;
          best_d = w.d;
          best_f = w.f;
          return;
        }
        if (!start_in_box) return;  // no candidate can pass
        refused[winner] = true;
      }
    };
    const P3 centre = best_d;
    try_round(centre, {0.08, 0.16, 0.3, 0.45});
    if (!start_in_box) {  // it cannot move until its eight cells change
      settle(self, 1);
      return false;
    }
    const P3 centre2 = best_d;
    try_round(centre2, {0.02, 0.04});
    if (best > start) {
      out.index = self;
      for (int a = 0; a < 3; ++a) out.v[a] = v[a];
      out.d = best_d;
      out.f = best_f;
      return true;
    }
    settle(self, any_candidate ? kGuardReach : 1);  // without candidates, no guard ran
    return false;
  }

  const Field<T>& field_;
  const BitGrid& grid_;
  GridVertices& gv_;
  const MacetCaseTable& table_;
  MacetSearchParams params_;
  std::vector<P3> dirs_;
  // Crossing positions per crossed edge (global sample coordinates), slots by grid vertex.
  std::vector<std::uint32_t> xoff_;
  ScratchVector<P3> xpos_;
  tbb::enumerable_thread_specific<std::vector<Proposal>> proposals_;
  // Per grid vertex: the colour step (counted over all sweeps) that last moved it, the step at
  // which a visit last left it in place (-1: never, or visited since), and how far around it a
  // move calls for a new visit.
  std::vector<int> last_moved_, settled_at_;
  std::vector<std::int8_t> settled_reach_;
  int step_ = 0;
  Progress* progress_ = nullptr;
};

template <class T>
void macet_local_search(const Field<T>& field, const BitGrid& grid, GridVertices& gv,
                        const MacetCaseTable& table, int sweeps, Progress* progress = nullptr) {
  if (sweeps <= 0) return;
  // Stage::MacetSearch counts rows of grid vertices: two passes to set up, one per colour step.
  progress_begin(progress, Stage::MacetSearch,
                 gv.box.extent(1) * gv.box.extent(2) * (2 + std::int64_t{sweeps} * kSearchColours));
  LocalSearch<T> search(field, grid, gv, table, MacetSearchParams{}, progress);
  for (int s = 0; s < sweeps; ++s) search.sweep();
}

}  // namespace isotile::detail
