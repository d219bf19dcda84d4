// Macet's Max mode: a local search per grid vertex that raises the worst triangles around it.
// Internal to core/.
//
// Moving grid vertex v changes only the crossings on its own (up to six) crossed edges, and those
// only appear in triangles of the eight cells around v. For every grid vertex whose affected
// triangles include one worse than kGoal, the search tries displacements around the current one
// (26 directions at a few radii, then a finer round around the best) and keeps the one that raises
// the minimum radius ratio of the affected triangles, subject to
//   * the vertex keeps its side of the surface (so every edge still brackets a crossing and the
//     topology stays MC's),
//   * it stays within max_move voxels of its grid position,
//   * no affected triangle turns over (its normal keeps a positive dot product with the current
//     one),
//   * the affected triangles intersect each other and the triangles of the 4x4x4 cells around v
//     in no more pairs than before.
// Determinism: vertices are swept in eight colours by the parity of their GLOBAL coordinates.
// Two vertices of one colour differ by two samples along some axis, so they share no cell and no
// crossed edge: a colour's vertices move in parallel without seeing each other's moves (the
// guard's outer cells, which may hold another moving vertex of the colour, are read from a
// snapshot taken when the step began), and the result is the same for any thread count and any
// brick cut. Each colour step lets a change travel two samples (the guard's reach), which is why
// macet_halo grows by 16 per sweep.
#pragma once

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

template <class T>
class LocalSearch {
 public:
  LocalSearch(const Field<T>& field, const BitGrid& grid, GridVertices& gv,
              const MacetCaseTable& table, MacetSearchParams params)
      : field_(field), grid_(grid), gv_(gv), table_(table), params_(params) {
    // 26 unit directions.
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (!dx && !dy && !dz) continue;
          const double n = std::sqrt(double(dx * dx + dy * dy + dz * dz));
          dirs_.push_back({dx / n, dy / n, dz / n});
        }
  }

  void sweep() {
    for (int colour = 0; colour < 8; ++colour) {
      colour_step(colour);
      ++step_;
    }
  }

 private:
  bool inside(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return (grid_.row(j, k)[i >> 6] >> (i & 63)) & 1;
  }

  void colour_step(int colour) {
    // The guard reads crossings two samples away, where other vertices of this colour may be
    // moving: it reads them as they were when the step began.
    const std::size_t nv = gv_.disp.size();
    snap_disp_.resize(nv);
    snap_value_.resize(nv);
    last_moved_.resize(nv, -1);
    settled_at_.resize(nv, -1);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv), [&](const auto& range) {
      for (std::size_t n = range.begin(); n != range.end(); ++n) {
        snap_disp_[n] = gv_.disp[n];
        snap_value_[n] = gv_.value[n];
      }
    });
    const Box3& b = gv_.box;
    const VolumeView& view = field_.view;
    const int px = colour & 1, py = (colour >> 1) & 1, pz = (colour >> 2) & 1;
    // Local x with the wanted global parity sit at every other bit.
    const std::uint64_t even = 0x5555555555555555ull;
    const std::uint64_t parity_mask = ((view.box.lo[0] & 1) ^ px) ? ~even : even;
    const std::int64_t rows = b.extent(1) * b.extent(2);
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, rows), [&](const auto& range) {
      for (std::int64_t r = range.begin(); r != range.end(); ++r) {
        const std::int64_t j = b.lo[1] + r % gv_.ny, k = b.lo[2] + r / gv_.ny;
        if (((view.box.lo[1] + j) & 1) != py || ((view.box.lo[2] + k) & 1) != pz) continue;
        for (std::int64_t w = b.lo[0] >> 6; w <= (b.hi[0] - 1) >> 6; ++w) {
          const std::size_t word = static_cast<std::size_t>(r * gv_.words + w);
          for (std::uint64_t m = gv_.bits[word] & parity_mask; m; m &= m - 1)
            improve(w * 64 + std::countr_zero(m), j, k);
        }
      }
    });
  }

  // The crossing on edge (s, axis a) with the current displacements, except that grid vertex
  // `moved` uses (d, f) instead.
  P3 crossing(const std::int64_t s[3], int a, std::uint32_t moved, const P3& d, double f) const {
    std::int64_t q[3] = {s[0], s[1], s[2]};
    ++q[a];
    const std::uint32_t i0 = gv_.index(s[0], s[1], s[2]), i1 = gv_.index(q[0], q[1], q[2]);
    const P3& d0 = i0 == moved ? d : gv_.disp[i0];
    const P3& d1 = i1 == moved ? d : gv_.disp[i1];
    const double f0 = i0 == moved ? f : gv_.value[i0], f1 = i1 == moved ? f : gv_.value[i1];
    const P3 p0 = field_.global(s[0], s[1], s[2], d0);
    const P3 p1 = field_.global(q[0], q[1], q[2], d1);
    const bool straight = d0 == P3{0, 0, 0} && d1 == P3{0, 0, 0};
    const double t = edge_crossing(field_, grid_, s, q, p0, p1, f0, f1, straight);
    return {p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]), p0[2] + t * (p1[2] - p0[2])};
  }

  // The crossing on edge (s, axis a) with the displacements of the step's snapshot.
  P3 snapshot_crossing(const std::int64_t s[3], int a) const {
    std::int64_t q[3] = {s[0], s[1], s[2]};
    ++q[a];
    const std::uint32_t i0 = gv_.index(s[0], s[1], s[2]), i1 = gv_.index(q[0], q[1], q[2]);
    const P3 p0 = field_.global(s[0], s[1], s[2], snap_disp_[i0]);
    const P3 p1 = field_.global(q[0], q[1], q[2], snap_disp_[i1]);
    const double f0 = snap_value_[i0], f1 = snap_value_[i1];
    const bool straight = snap_disp_[i0] == P3{0, 0, 0} && snap_disp_[i1] == P3{0, 0, 0};
    const double t = edge_crossing(field_, grid_, s, q, p0, p1, f0, f1, straight);
    return {p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]), p0[2] + t * (p1[2] - p0[2])};
  }

  int cell_case(const std::int64_t o[3]) const {
    int cs = 0;
    for (int corner = 0; corner < 8; ++corner)
      cs |= int(inside(o[0] + (corner & 1), o[1] + ((corner >> 1) & 1), o[2] + ((corner >> 2) & 1)))
            << corner;
    return cs;
  }

  // Whether a grid vertex of the 3x3x3 block around v moved at or after `step`.
  bool block_moved_since(const std::int64_t v[3], int step) const {
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const std::int64_t q[3] = {v[0] + dx, v[1] + dy, v[2] + dz};
          if (gv_.contains(q[0], q[1], q[2]) && last_moved_[gv_.index(q[0], q[1], q[2])] >= step)
            return true;
        }
    return false;
  }

  void improve(std::int64_t i, std::int64_t j, std::int64_t k) {
    const VolumeView& view = field_.view;
    const std::int64_t v[3] = {i, j, k};
    const std::uint32_t self = gv_.index(i, j, k);
    // A vertex whose last visit left it in place without consulting the guard (its triangles
    // good enough, or no candidate better) would do the same again until a vertex of its block
    // moves (its eight cells' crossings depend on that block only): skipping it then gives
    // exactly what a visit would. Vertices of one colour are never in each other's
    // blocks, so the test reads nothing that moves during this step.
    if (settled_at_[self] >= 0 && !block_moved_since(v, settled_at_[self])) return;
    settled_at_[self] = -1;
    const bool in = inside(i, j, k);

    // The affected triangles: those of the eight cells around v that use a crossing on one of
    // v's edges. Crossings are slots: fixed ones computed once, moving ones per candidate.
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
    const P3 zero{0, 0, 0};
    // Crossings by edge, for the guard's vertex identities: edges with both ends in v +- 2.
    auto edge_code = [&](const std::int64_t s[3], int a) {
      return static_cast<std::uint32_t>(
          (((s[2] - v[2] + 2) * 5 + (s[1] - v[1] + 2)) * 5 + (s[0] - v[0] + 2)) * 3 + a);
    };
    std::array<std::uint32_t, 8 * 12> fixed_code{};
    std::array<std::uint32_t, 6> moving_code{};

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
      std::int16_t slot[12];
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
          if (m == n_moving) {
            moving_code[n_moving] = edge_code(s, a);
            moving[n_moving++] = {{s[0], s[1], s[2]}, a};
          }
          slot[e] = static_cast<std::int16_t>(-1 - m);
        } else {
          slot[e] = static_cast<std::int16_t>(n_fixed);
          fixed_code[n_fixed] = edge_code(s, a);
          fixed[n_fixed++] = crossing(s, a, ~0u, zero, 0);
        }
      }
      const auto& tt = table_.triangles[cs];
      for (int t = 0; t < nt; ++t) {
        const TriRef ref{{slot[tt[3 * t]], slot[tt[3 * t + 1]], slot[tt[3 * t + 2]]}};
        if (ref.v[0] < 0 || ref.v[1] < 0 || ref.v[2] < 0)
          tris[n_tris++] = ref;
        else
          statics[n_statics++] = ref;
      }
    }
    if (n_tris == 0) {
      settled_at_[self] = step_;
      return;
    }

    // Moving crossings for the candidate (cand_d, cand_f), computed when first needed: most
    // candidates are rejected after a crossing or two (see score).
    std::array<P3, 6> mpos{};
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
      for (int m = 0; m < n_moving; ++m)
        mpos[m] = crossing(moving[m].s, moving[m].axis, self, d, f);
      placed = (1u << n_moving) - 1;
    };
    auto pos = [&](std::int16_t s) -> const P3& {
      if (s >= 0) return fixed[s];
      const int m = -1 - s;
      if (!((placed >> m) & 1)) {
        mpos[m] = crossing(moving[m].s, moving[m].axis, self, cand_d, cand_f);
        placed |= 1u << m;
      }
      return mpos[m];
    };
    std::array<P3, 8 * mc::kMaxTrianglesPerCase> normal0{};
    std::array<double, 8 * mc::kMaxTrianglesPerCase> q0{};
    std::array<int, 8 * mc::kMaxTrianglesPerCase> order{};
    for (int t = 0; t < n_tris; ++t) order[t] = t;
    // The minimum radius ratio of the affected triangles, -1 when one turns over, and with a
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

    // Intersection guard: a move may not raise the number of intersecting pairs (rule of
    // core/mesh/self_intersections.h, on the float coordinates) between a triangle that involves a
    // moving crossing and any triangle of the 4x4x4 cells around v, read as they were when the
    // colour step began. Without it the search folds neighbouring sheets of thin features
    // through each other (bonsai: 42 intersecting pairs against MC's 28 and Fast's 0; lobster:
    // 16 when the guard saw the eight cells around v only). Vertices are identified by edge.
    struct Corners {
      std::array<Vec3f, 3> p;
      std::array<std::uint32_t, 3> id;
      Vec3f lo, hi;
      bool live;
    };
    auto make_corners = [](const P3* x[3], const std::uint32_t id[3]) {
      Corners c;
      for (int k = 0; k < 3; ++k) {
        c.p[k] = {static_cast<float>((*x[k])[0]), static_cast<float>((*x[k])[1]),
                  static_cast<float>((*x[k])[2])};
        c.id[k] = id[k];
      }
      for (int a = 0; a < 3; ++a) {
        c.lo[a] = std::min({c.p[0][a], c.p[1][a], c.p[2][a]});
        c.hi[a] = std::max({c.p[0][a], c.p[1][a], c.p[2][a]});
      }
      c.live = triangle_has_area(c.p);
      return c;
    };
    auto corners = [&](const TriRef& t) {
      const P3* x[3];
      std::uint32_t id[3];
      for (int k = 0; k < 3; ++k) {
        x[k] = &pos(t.v[k]);
        id[k] = t.v[k] >= 0 ? fixed_code[t.v[k]] : moving_code[-1 - t.v[k]];
      }
      return make_corners(x, id);
    };
    auto meet = [](const Corners& a, const Corners& b) {
      for (int k = 0; k < 3; ++k)
        if (a.hi[k] < b.lo[k] || b.hi[k] < a.lo[k]) return false;
      return a.live && b.live && triangles_intersect(a.p, a.id, b.p, b.id);
    };
    // The other triangles: the eight cells' fixed ones, then the 56 cells around them (built on
    // the first candidate that needs the guard: most vertices never get that far).
    std::array<Corners, 64 * mc::kMaxTrianglesPerCase> others;
    int n_others = 0;
    for (int t = 0; t < n_statics; ++t) others[n_others++] = corners(statics[t]);
    bool ring_built = false;
    auto build_ring = [&]() {
      ring_built = true;
      for (int c = 0; c < 64; ++c) {
        const int d[3] = {c % 4 - 2, (c / 4) % 4 - 2, c / 16 - 2};
        if (d[0] >= -1 && d[0] <= 0 && d[1] >= -1 && d[1] <= 0 && d[2] >= -1 && d[2] <= 0)
          continue;  // one of the eight cells
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
        std::uint32_t id[12];
        for (unsigned em = table_.edge_mask[cs]; em; em &= em - 1) {
          const int e = std::countr_zero(em);
          const int c0 = mc::kEdgeCorners[e][0];
          const std::int64_t s[3] = {o[0] + (c0 & 1), o[1] + ((c0 >> 1) & 1),
                                     o[2] + ((c0 >> 2) & 1)};
          x[e] = snapshot_crossing(s, e / 4);
          id[e] = edge_code(s, e / 4);
        }
        const auto& tt = table_.triangles[cs];
        for (int t = 0; t < nt; ++t) {
          const P3* px[3] = {&x[tt[3 * t]], &x[tt[3 * t + 1]], &x[tt[3 * t + 2]]};
          const std::uint32_t pid[3] = {id[tt[3 * t]], id[tt[3 * t + 1]], id[tt[3 * t + 2]]};
          others[n_others++] = make_corners(px, pid);
        }
      }
    };
    std::array<Corners, 8 * mc::kMaxTrianglesPerCase> moving_corners;
    auto intersecting_pairs = [&]() {
      int n = 0;
      for (int t = 0; t < n_tris; ++t) {
        moving_corners[t] = corners(tris[t]);
        if (!moving_corners[t].live) continue;
        for (int u = 0; u < n_others; ++u) n += meet(moving_corners[t], others[u]);
        for (int u = 0; u < t; ++u) n += meet(moving_corners[t], moving_corners[u]);
      }
      return n;
    };

    P3 best_d = gv_.disp[self];
    double best_f = gv_.value[self];
    place(best_d, best_f);
    double best = score(true);
    if (best >= params_.goal) {
      settled_at_[self] = step_;
      return;
    }
    std::stable_sort(order.begin(), order.begin() + n_tris,
                     [&](int x, int y) { return q0[x] < q0[y]; });
    const double start = best;
    const P3 start_d = best_d;
    const double start_f = best_f;
    int allowed_pairs = -1;
    // Called with candidate (d, f) placed; leaves it placed.
    auto guard_passes = [&](const P3& d, double f) {
      if (!ring_built) {
        build_ring();
        place(start_d, start_f);
        allowed_pairs = intersecting_pairs();
        place(d, f);
      }
      return intersecting_pairs() <= allowed_pairs;
    };

    // A round keeps the best-scoring candidate that passes the guard (the first in scan order
    // among equal scores). The guard is the costly test, so it runs only on the candidates that
    // beat the round's starting score, best first, until one passes.
    struct Candidate {
      double score;
      P3 d;
      double f;
    };
    std::array<Candidate, 26 * 4> candidates;
    bool any_candidate = false;
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
          const double f = field_.value(p);
          if ((f >= 0) != in) continue;
          stage(d, f);
          const double sc = score(false, best);
          if (sc > best) candidates[n++] = {sc, d, f};
        }
      any_candidate = any_candidate || n > 0;
      std::stable_sort(candidates.begin(), candidates.begin() + n,
                       [](const Candidate& x, const Candidate& y) { return x.score > y.score; });
      for (int c = 0; c < n; ++c) {
        place(candidates[c].d, candidates[c].f);
        if (!guard_passes(candidates[c].d, candidates[c].f)) continue;
        best = candidates[c].score;
        best_d = candidates[c].d;
        best_f = candidates[c].f;
        break;
      }
    };
    const P3 centre = best_d;
    try_round(centre, {0.08, 0.16, 0.3, 0.45});
    const P3 centre2 = best_d;
    try_round(centre2, {0.02, 0.04});
    if (best > start) {
      gv_.disp[self] = best_d;
      gv_.value[self] = best_f;
      last_moved_[self] = step_;
    } else if (!any_candidate) {
      // Nothing beat the start, which depends on the block only (the guard never ran).
      settled_at_[self] = step_;
    }
  }

  const Field<T>& field_;
  const BitGrid& grid_;
  GridVertices& gv_;
  const MacetCaseTable& table_;
  MacetSearchParams params_;
  std::vector<P3> dirs_;
  std::vector<P3> snap_disp_;  // the displacements and values when the colour step began
  std::vector<double> snap_value_;
  // Per grid vertex: the colour step (counted over all sweeps) that last moved it, and the step
  // at which it was last found good enough to leave (-1: never, or visited since).
  std::vector<int> last_moved_, settled_at_;
  int step_ = 0;
};

template <class T>
void macet_local_search(const Field<T>& field, const BitGrid& grid, GridVertices& gv,
                        const MacetCaseTable& table, int sweeps) {
  LocalSearch<T> search(field, grid, gv, table, MacetSearchParams{});
  for (int s = 0; s < sweeps; ++s) search.sweep();
}

}  // namespace isotile::detail
