// Triangle quality: the radius ratio q = 2 r_in / R_circ = (b+c-a)(c+a-b)(a+b-c) / (a b c), 1 for
// an equilateral triangle and 0 for a degenerate one (the 0..1 form of the paper's Table I; VTK's
// "radius ratio" is the inverse R/r).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/mesh/mesh.h"

namespace isotile {

// Radius ratio of one triangle, computed in double; 0 when any edge has zero length.
double radius_ratio(const Vec3f& a, const Vec3f& b, const Vec3f& c);

// The same from the three edge lengths.
inline double radius_ratio_of_lengths(double la, double lb, double lc) {
  if (la == 0 || lb == 0 || lc == 0) return 0;
  const double q = (lb + lc - la) * (lc + la - lb) * (la + lb - lc) / (la * lb * lc);
  // Rounding can push collinear triangles slightly below 0 and equilateral ones above 1, and
  // non-finite coordinates give NaN, which would break sorting; all of those clamp into [0, 1].
  if (!(q > 0)) return 0;
  return q < 1 ? q : 1;
}

// A quad as two triangles along the diagonal whose worse triangle is better (0-2 on a tie), as
// every part of isotile takes quads where triangles are needed: the quality measures,
// simplification and STL, which holds triangles only.
struct QuadSplit {
  std::array<Tri, 2> triangles;
  std::array<double, 2> quality;  // their radius ratios
};
// Throws InputError where the quad references a vertex past `positions`.
QuadSplit split_quad(const std::vector<Vec3f>& positions, const Quad& q);

struct QualityStats {
  std::uint64_t triangles = 0;   // quads count as their two triangles (better diagonal)
  std::uint64_t degenerate = 0;  // q < 1e-6 (zero area or collinear)
  double min = 0, mean = 0, max = 0;
  double q001 = 0, q01 = 0;  // 0.1% and 1% quantiles (lower tail)
  double median = 0;
  std::array<std::uint64_t, 20> histogram{};  // 20 bins of width 0.05 over [0, 1]
};

// How one triangle of radius ratio q counts in QualityStats (in core and in the tiler's stream
// alike): degenerate below 1e-6, and its histogram bin.
inline bool degenerate_ratio(double q) {
  return q < 1e-6;
}
inline std::size_t histogram_bin(double q) {
  return std::min<std::size_t>(static_cast<std::size_t>(q * 20), 19);
}

// The sum of radius ratios behind QualityStats::mean, in 2^-60 units in 128 bits: integer
// addition does not depend on the order, so the mean comes out the same bits for any thread
// count, in core and in the tiler's stream of bricks alike, whichever process added which
// triangle (a double sum depends on the grouping, and the stream's grouping is the bricks').
struct RatioSum {
  std::uint64_t lo = 0, hi = 0;
  void add(double q) { add_fixed(static_cast<std::uint64_t>(std::clamp(q, 0.0, 8.0) * 0x1p60), 0); }
  void add(const RatioSum& o) { add_fixed(o.lo, o.hi); }
  double value() const {
    return std::ldexp(static_cast<double>(hi), 4) + std::ldexp(static_cast<double>(lo), -60);
  }

 private:
  void add_fixed(std::uint64_t l, std::uint64_t h) {
    lo += l;
    hi += h + (lo < l ? 1 : 0);
  }
};

// Deterministic for any thread count (integer counts and RatioSum). Throws InputError where a
// face references a vertex past the positions (check_face_indices).
QualityStats triangle_quality(const Mesh& mesh);

}  // namespace isotile
