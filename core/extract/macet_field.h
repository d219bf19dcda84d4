// What Macet's passes share: the volume seen as its trilinear interpolant, root finding along a
// displaced edge, and the grid vertices that carry displacements. Internal to core/.
//
// Samples are addressed by the view's own indices; points (displaced vertices, crossings) are in
// GLOBAL sample coordinates (voxel units), so their arithmetic is the same in every view. Every
// value is computed from the same samples with the same arithmetic whatever the view is, as long as
// the samples involved lie in the view: gradients are one-sided only at the border of the whole
// volume, and a displaced point is clamped to the whole volume, never to the view. The halo
// (macet_halo) keeps every point whose result is emitted that far from the view's border.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/extract/inside_bits.h"
#include "core/extract/isovalue_ties.h"
#include "core/extract/scratch_vector.h"
#include "core/volume/volume.h"

namespace isotile::detail {

using P3 = std::array<double, 3>;

// Fast mode, step 1, the push: a crossing closer than kMacetReach (in edge lengths) to a grid
// vertex pushes the vertex straight back along that edge by the shortfall; the pushes of its edges
// add up, capped at kMacetPushCap voxels. Step 2, one smoothing pass through the end points: each
// grid vertex moves within its tangent plane by the (1 - t)-weighted mean of the umbrella
// Laplacians of the crossings on its edges (t: the crossing's distance from the vertex in edge
// lengths), capped at kMacetSmoothCap voxels in all. Every move is halved (up to kMacetHalvings
// times, then dropped) until the displaced vertex keeps its side and stays at least kMacetGuard
// (push) or kMacetSmoothGuard (smoothing) times as far from the isovalue as its sample.
// docs/macet.md has the measurements behind these values. The GL backends (shaders/macet_gl.cpp)
// hand these same constants to their shaders.
inline constexpr double kMacetReach = 0.4;
inline constexpr double kMacetPushCap = 0.45;
inline constexpr double kMacetSmoothCap = 0.6;
inline constexpr double kMacetGuard = 1.0;
inline constexpr double kMacetSmoothGuard = 0.7;
inline constexpr int kMacetHalvings = 4;

template <class T>
struct Field {
  Field(const VolumeView& v, double iso_value) : view(v), data(v.typed<T>()), iso(iso_value) {
    for (int a = 0; a < 3; ++a) {
      lo_clamp[a] = 0.0;
      hi_clamp[a] = static_cast<double>(v.global_dims[a] - 1);
      // cell_of's two clamps (to the whole volume's cells, then to the view's) in one: the view's
      // cells lie inside the volume's, so clamping to the view's global range is the same.
      const std::int64_t g_hi = std::max<std::int64_t>(v.global_dims[a] - 2, 0);
      const std::int64_t l_hi = std::max<std::int64_t>(v.dims[a] - 2, 0);
      cell_lo[a] = v.box.lo[a];
      cell_hi[a] = std::max(cell_lo[a], std::min(g_hi, v.box.lo[a] + l_hi));
      step[a] = v.dims[a] > 1 ? v.strides[a] : 0;
    }
  }

  double sample(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return static_cast<double>(data[view.offset(i, j, k)]);
  }

  // f - iso of the trilinear interpolant at local point p. The cell is clamped to the view, which
  // only matters for points the halo keeps away from emitted results.
  double value(const P3& p) const {
    Corners c;
    return value(p, c);
  }

  // The eight samples of the cell last looked up, so that a search converging inside one cell
  // reads them once.
  struct Corners {
    std::int64_t cell[3] = {-1, -1, -1};
    double s[8] = {};
  };

  // value(p), reusing `c` when p lies in the same cell (same samples, same arithmetic).
  double value(const P3& p, Corners& c) const {
    double u[3];
    std::int64_t gc[3];
    for (int a = 0; a < 3; ++a) {
      gc[a] = global_cell(p[a], a);
      u[a] = p[a] - static_cast<double>(gc[a]);
    }
    if (gc[0] != c.cell[0] || gc[1] != c.cell[1] || gc[2] != c.cell[2]) {
      const std::int64_t sx = step[0], sy = step[1], sz = step[2];
      const T* b = data + (gc[0] - view.box.lo[0]) * view.strides[0] +
                   (gc[1] - view.box.lo[1]) * view.strides[1] +
                   (gc[2] - view.box.lo[2]) * view.strides[2];
      c.s[0] = b[0], c.s[1] = b[sx], c.s[2] = b[sy], c.s[3] = b[sx + sy];
      c.s[4] = b[sz], c.s[5] = b[sx + sz], c.s[6] = b[sy + sz], c.s[7] = b[sx + sy + sz];
      for (int a = 0; a < 3; ++a) c.cell[a] = gc[a];
    }
    const double* q = c.s;
    const double x00 = q[0] + u[0] * (q[1] - q[0]), x10 = q[2] + u[0] * (q[3] - q[2]);
    const double x01 = q[4] + u[0] * (q[5] - q[4]), x11 = q[6] + u[0] * (q[7] - q[6]);
    const double y0 = x00 + u[1] * (x10 - x00), y1 = x01 + u[1] * (x11 - x01);
    return y0 + u[2] * (y1 - y0) - iso;
  }

  // The global index of the cell holding coordinate x along axis a (see cell_of).
  std::int64_t global_cell(double x, int a) const {
    return std::clamp(static_cast<std::int64_t>(std::floor(x)), cell_lo[a], cell_hi[a]);
  }

  // Global coordinates of local sample (i, j, k) moved by d.
  P3 global(std::int64_t i, std::int64_t j, std::int64_t k, const P3& d = {0, 0, 0}) const {
    return {static_cast<double>(view.box.lo[0] + i) + d[0],
            static_cast<double>(view.box.lo[1] + j) + d[1],
            static_cast<double>(view.box.lo[2] + k) + d[2]};
  }

  // Central differences at a sample, in voxel units; one-sided only at the whole volume's border
  // (and at the view's, which the halo keeps away from emitted results).
  P3 gradient(std::int64_t i, std::int64_t j, std::int64_t k) const {
    const std::int64_t p[3] = {i, j, k};
    P3 g{};
    if (i > 0 && j > 0 && k > 0 && i + 1 < view.dims[0] && j + 1 < view.dims[1] &&
        k + 1 < view.dims[2]) {
      // Inside the view (so inside the volume): central differences, as below with h = 2.
      const T* c = data + view.offset(i, j, k);
      for (int a = 0; a < 3; ++a)
        g[a] =
            (static_cast<double>(c[view.strides[a]]) - static_cast<double>(c[-view.strides[a]])) /
            2.0;
      return g;
    }
    for (int a = 0; a < 3; ++a) {
      const std::int64_t global = view.box.lo[a] + p[a];
      std::int64_t lo[3] = {i, j, k}, hi[3] = {i, j, k};
      if (global > 0 && p[a] > 0) lo[a] = p[a] - 1;
      if (global + 1 < view.global_dims[a] && p[a] + 1 < view.dims[a]) hi[a] = p[a] + 1;
      const double h = static_cast<double>(hi[a] - lo[a]);
      g[a] = h > 0 ? (sample(hi[0], hi[1], hi[2]) - sample(lo[0], lo[1], lo[2])) / h : 0.0;
    }
    return g;
  }

  // Trilinear interpolation of the sample gradients at p, in world units.
  P3 world_gradient(const P3& p) const {
    std::int64_t c[3];
    double u[3];
    for (int a = 0; a < 3; ++a) {
      const std::int64_t ci = cell_of(p[a], a);
      c[a] = ci;
      u[a] = std::clamp(p[a] - static_cast<double>(ci + view.box.lo[a]), 0.0, 1.0);
    }
    P3 g{};
    for (int corner = 0; corner < 8; ++corner) {
      const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
      const std::int64_t i = std::min(c[0] + dx, view.dims[0] - 1);
      const std::int64_t j = std::min(c[1] + dy, view.dims[1] - 1);
      const std::int64_t k = std::min(c[2] + dz, view.dims[2] - 1);
      const double w = (dx ? u[0] : 1 - u[0]) * (dy ? u[1] : 1 - u[1]) * (dz ? u[2] : 1 - u[2]);
      const P3 gc = gradient(i, j, k);
      for (int a = 0; a < 3; ++a) g[a] += w * gc[a];
    }
    for (int a = 0; a < 3; ++a) g[a] /= view.spacing[a];
    return g;
  }

  // The cell holding coordinate x along axis a, local to the view: clamped to the whole volume's
  // cells first, so the choice (and the arithmetic) is the same in every view holding that cell,
  // then to the view's (which only matters for points the halo keeps away from emitted results).
  std::int64_t cell_of(double x, int a) const { return global_cell(x, a) - view.box.lo[a]; }

  // Where grid vertex v displaced by d lands: inside the whole volume, and on the volume's border
  // plane when v is (so the mesh keeps ending exactly on the border, as MC's does).
  P3 displaced(const std::int64_t v[3], const P3& d) const {
    P3 p;
    for (int a = 0; a < 3; ++a) {
      const std::int64_t g = view.box.lo[a] + v[a];
      const double x = static_cast<double>(g);
      p[a] = (g == 0 || g == view.global_dims[a] - 1)
                 ? x
                 : std::clamp(x + d[a], lo_clamp[a], hi_clamp[a]);
    }
    return p;
  }

  const VolumeView& view;
  const T* data;
  double iso;
  double lo_clamp[3], hi_clamp[3];
  std::int64_t cell_lo[3], cell_hi[3];  // global cell range value() and cell_of() clamp to
  std::int64_t step[3];                 // stride to the next sample, 0 along a 1-sample axis
};

// find_root stops at a point whose |f - iso| is at most this fraction of the ends' difference, or
// once its bracket is narrower than kRootWidth (of the segment).
inline constexpr double kRootTolerance = 1e-5;
inline constexpr double kRootWidth = 1e-5;

// The crossing of f = iso on the segment p0 -> p1 whose ends have f - iso = f0 >= 0 > f1 or
// f0 < 0 <= f1: Illinois-modified regula falsi on the trilinear interpolant, which converges
// superlinearly and never leaves the bracket. Returns the parameter t in [0, 1].
// `cache`: the cell samples last read, kept across calls that search near one another (the same
// samples give the same arithmetic, so the result does not depend on it).
template <class T>
double find_root(const Field<T>& field, const P3& p0, const P3& p1, double f0, double f1,
                 typename Field<T>::Corners* cache = nullptr) {
  if (p0 == p1) return 0.5;
  double lo = 0, hi = 1, flo = f0, fhi = f1;
  const double tol = kRootTolerance * std::abs(f0 - f1);
  int side = 0;
  double t = 0.5;
  typename Field<T>::Corners own;
  typename Field<T>::Corners& corners = cache ? *cache : own;
  for (int it = 0; it < 24; ++it) {
    const double denom = flo - fhi;
    t = denom != 0 ? lo + (hi - lo) * flo / denom : 0.5 * (lo + hi);
    if (!(t > lo && t < hi)) t = 0.5 * (lo + hi);
    if (hi - lo < kRootWidth) break;
    const P3 p{p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]),
               p0[2] + t * (p1[2] - p0[2])};
    const double f = field.value(p, corners);
    if (std::abs(f) <= tol) break;
    // Inside is f >= 0, as in the classification. The Illinois step, selected rather than
    // branched on (its branches are unpredictable): the end that keeps its side twice in a row
    // has its value halved.
    const bool same = (f >= 0) == (flo >= 0);
    const double kept_flo = side == 1 ? flo * 0.5 : flo, kept_fhi = side == -1 ? fhi * 0.5 : fhi;
    lo = same ? t : lo;
    hi = same ? hi : t;
    flo = same ? f : kept_flo;
    fhi = same ? kept_fhi : f;
    side = same ? -1 : 1;
  }
  return t;
}

// Whether inside sample s (local indices) has two or more neighbours outside, i.e. two or more
// crossed edges (core/extract/isovalue_ties.h). Neighbours beyond the view do not count: the halo
// keeps emitted results away from there.
inline bool spreading_tie(const BitGrid& grid, const std::int64_t s[3]) {
  const std::int64_t dims[3] = {grid.nx, grid.ny, grid.nz};
  int outside = 0;
  for (int a = 0; a < 3; ++a)
    for (int dir = -1; dir <= 1; dir += 2) {
      std::int64_t q[3] = {s[0], s[1], s[2]};
      q[a] += dir;
      if (q[a] >= 0 && q[a] < dims[a])
        outside += !((grid.row(q[1], q[2])[q[0] >> 6] >> (q[0] & 63)) & 1);
    }
  return outside >= 2;
}

// The parameter of the crossing on the segment p0 -> p1 between the displaced grid vertices at
// local samples s0 and s1, where f - iso is f0 and f1 (one >= 0, the other < 0). `straight`:
// both are undisplaced, so the trilinear interpolant is linear along the segment (also used for
// Fast's linear estimates). An end still at the isovalue whose sample has two or more crossed
// edges gets its crossing kTieOffset from it (core/extract/isovalue_ties.h). "Still at the
// isovalue": exactly, or, for a tie (a sample at the isovalue) moved along the level set, within
// find_root's tolerance of it, where the root search would stop at the end point itself: on label
// maps a tie moved by the push or the smoothing lands where the interpolant is the isovalue up to
// rounding (4.4e-16) or nearly, and all its crossings would then fall on it or within 1e-6 of it.
// A float32 sample holding the float nearest the isovalue is a tie too: float32 data of 0.1 at
// --iso 0.1 (whose double lies 1.5e-9 below 0.1f) had the crossings of such samples within 1.5e-8
// of them, and 466 degenerate triangles of 1,016 on a ball where the tie 0.10000000149011612 gave
// none.
template <class T>
double edge_crossing(const Field<T>& field, const BitGrid& grid, const std::int64_t s0[3],
                     const std::int64_t s1[3], const P3& p0, const P3& p1, double f0, double f1,
                     bool straight, typename Field<T>::Corners* cache = nullptr) {
  const double tol = kRootTolerance * std::abs(f0 - f1);
  const auto at_tie = [&](double f, const std::int64_t s[3]) {
    if (f == 0) return true;
    if (std::abs(f) > tol) return false;
    const double v = field.sample(s[0], s[1], s[2]);
    return v == field.iso ||
           (std::is_same_v<T, float> && v == static_cast<double>(static_cast<float>(field.iso)));
  };
  if (at_tie(f0, s0) && spreading_tie(grid, s0)) return kTieOffset;
  if (at_tie(f1, s1) && spreading_tie(grid, s1)) return 1 - kTieOffset;
  return straight ? f0 / (f0 - f1) : find_root(field, p0, p1, f0, f1, cache);
}

// Grid vertices touching a crossed edge, inside a box of samples; each gets a dense index (its
// rank in x-fastest order), found from bit masks and popcounts. Holds one displacement and the
// value f - iso at the displaced point per vertex.
struct GridVertices {
  Box3 box;  // local samples [lo, hi)
  std::int64_t words = 0, ny = 0;
  ScratchVector<std::uint64_t> bits;    // per row of the box, bit i = local x i (as in BitGrid)
  ScratchVector<std::uint32_t> prefix;  // vertices before each word
  ScratchVector<P3> disp;               // displacement, voxel units (written by the push)
  ScratchVector<double> value;          // f - iso at the displaced vertex

  std::int64_t row(std::int64_t j, std::int64_t k) const {
    return (k - box.lo[2]) * ny + (j - box.lo[1]);
  }
  // Index of the vertex at local sample (i, j, k), which must be a touched vertex in the box.
  std::uint32_t index(std::int64_t i, std::int64_t j, std::int64_t k) const {
    const std::size_t w = static_cast<std::size_t>(row(j, k) * words + (i >> 6));
    const std::uint64_t below = (std::uint64_t{1} << (i & 63)) - 1;
    return prefix[w] + static_cast<std::uint32_t>(std::popcount(bits[w] & below));
  }
  bool contains(std::int64_t i, std::int64_t j, std::int64_t k) const {
    if (i < box.lo[0] || j < box.lo[1] || k < box.lo[2] || i >= box.hi[0] || j >= box.hi[1] ||
        k >= box.hi[2])
      return false;
    return (bits[static_cast<std::size_t>(row(j, k) * words + (i >> 6))] >> (i & 63)) & 1;
  }
};

}  // namespace isotile::detail
