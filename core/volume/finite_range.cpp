#include "core/volume/finite_range.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>

#include "core/volume/volume_io.h"

namespace isotile {
namespace {

struct Scan {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  bool finite = true;
};

// kLanes samples of T: two SSE registers' worth, held as two GCC vectors (one register each; a
// single 32-byte vector compiled to slower code here), each lane with its own minimum and maximum,
// so that the loop runs on packed min/max for every sample type without reordering any one
// comparison chain (the compiler would not vectorise a floating-point reduction it must not
// reorder). `v < lo ? v : lo` on vectors compiles to SSE's min, whose NaN handling is that
// expression's. The lanes run on over every row of a task and are folded once at its end.
template <class T>
inline constexpr int kLanes = static_cast<int>(32 / sizeof(T));

template <class T>
Scan scan_rows(const VolumeView& view, std::int64_t row_begin, std::int64_t row_end) {
  constexpr int L = kLanes<T>;
  constexpr bool floating = std::is_floating_point_v<T>;
  const T* data = view.typed<T>();
  const std::int64_t n = view.dims[0], ny = view.dims[1], stride = view.strides[0];
  // Every bound starts past every sample (floating point: infinities). A NaN sample never becomes
  // a bound: `v < lo ? v : lo` and SSE's min and max keep `lo` when v is NaN.
  const T start_lo = floating ? std::numeric_limits<T>::infinity() : std::numeric_limits<T>::max();
  const T start_hi =
      floating ? -std::numeric_limits<T>::infinity() : std::numeric_limits<T>::lowest();
  typedef T Lanes __attribute__((vector_size(16)));
  constexpr int W = 16 / static_cast<int>(sizeof(T));
  Lanes lo_l[2], hi_l[2], nonfinite_l[2];
  for (int h = 0; h < 2; ++h) {
    lo_l[h] = Lanes{} + start_lo;
    hi_l[h] = Lanes{} + start_hi;
    nonfinite_l[h] = Lanes{};
  }
  T lo = start_lo, hi = start_hi, nonfinite = 0;
  for (std::int64_t r = row_begin; r != row_end; ++r) {
    const T* row = data + view.offset(0, r % ny, r / ny);
    std::int64_t i = 0;
    if (stride == 1)
      for (; i + L <= n; i += L)
        for (int h = 0; h < 2; ++h) {
          Lanes v;
          std::memcpy(&v, row + i + h * W, sizeof v);
          lo_l[h] = v < lo_l[h] ? v : lo_l[h];
          hi_l[h] = v > hi_l[h] ? v : hi_l[h];
          if constexpr (floating) nonfinite_l[h] += v - v;
        }
    for (; i < n; ++i) {
      const T v = row[i * stride];
      lo = v < lo ? v : lo;
      hi = v > hi ? v : hi;
      if constexpr (floating) nonfinite += v - v;
    }
  }
  for (int h = 0; h < 2; ++h)
    for (int l = 0; l < W; ++l) {
      lo = lo_l[h][l] < lo ? lo_l[h][l] : lo;
      hi = hi_l[h][l] > hi ? hi_l[h][l] : hi;
      if constexpr (floating) nonfinite += nonfinite_l[h][l];
    }
  Scan s;
  s.lo = static_cast<double>(lo);
  s.hi = static_cast<double>(hi);
  if constexpr (floating) s.finite = nonfinite == T(0);
  return s;
}

template <class T>
Scan typed_scan(const VolumeView& view) {
  const Index3& d = view.dims;
  // Rows of x, in y-then-z order; min and max are order-independent (NaN samples are skipped), so
  // the split TBB picks cannot change the result but for the sign of a zero bound (see below).
  const std::int64_t rows = d[1] * d[2];
  const std::int64_t grain = std::max<std::int64_t>(1, (std::int64_t{1} << 16) / d[0]);
  return tbb::parallel_reduce(
      tbb::blocked_range<std::int64_t>(0, rows, grain), Scan{},
      [&](const tbb::blocked_range<std::int64_t>& r, Scan acc) {
        const Scan s = scan_rows<T>(view, r.begin(), r.end());
        acc.lo = std::min(acc.lo, s.lo);
        acc.hi = std::max(acc.hi, s.hi);
        acc.finite = acc.finite && s.finite;
        return acc;
      },
      [](Scan a, const Scan& b) {
        a.lo = std::min(a.lo, b.lo);
        a.hi = std::max(a.hi, b.hi);
        a.finite = a.finite && b.finite;
        return a;
      });
}

Scan scan(const VolumeView& view) {
  return visit_scalar(view.type, [&](auto tag) { return typed_scan<decltype(tag)>(view); });
}

// + 0.0 turns a -0.0 bound into +0.0: which of the two zeros a lane meets first depends on where
// TBB split the rows, and the answer must not.
std::pair<double, double> bounds(const Scan& s) {
  return {s.lo + 0.0, s.hi + 0.0};
}

}  // namespace

std::pair<double, double> value_range(const VolumeView& view) {
  if (view.sample_count() <= 0) return {0.0, 0.0};
  const Scan s = scan(view);
  // Only an all-NaN volume leaves the bounds unset.
  if (s.lo > s.hi)
    return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  return bounds(s);
}

std::pair<double, double> finite_value_range(const VolumeView& view, const std::string& what) {
  if (view.sample_count() <= 0) return {0.0, 0.0};
  const Scan s = scan(view);
  // Throws, counting the NaN and Inf samples (or float64 ones past kLargestFloat64Sample) and
  // naming the first.
  if (!s.finite ||
      (view.type == ScalarType::Float64 && std::max(-s.lo, s.hi) > kLargestFloat64Sample))
    check_finite(view, what);
  return bounds(s);
}

}  // namespace isotile
