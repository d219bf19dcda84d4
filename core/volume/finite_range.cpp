#include "core/volume/finite_range.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <type_traits>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "core/volume/volume_io.h"

namespace isotile {
namespace {

struct Scan {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  bool finite = true;
};

// Lanes of two SSE registers' samples, each with its own minimum and maximum, so that the loop
// runs on packed min/max without reordering any one comparison chain. The compiler does that
// itself for integers; for floating point it may not (it would be a reduction it must not
// reorder), so those lanes are written with SSE2, whose min and max are the same comparisons
// (v < lo ? v : lo). The lanes run on over every row of a task and are folded once at its end.
template <class T>
inline constexpr int kLanes = static_cast<int>(32 / sizeof(T));

// Lanes of float or double: lo, hi, and the running sum of v - v, which is 0 while every sample
// is finite and NaN from the first NaN or Inf on.
template <class T>
struct FloatLanes {
  T lo[kLanes<T>], hi[kLanes<T>], nonfinite[kLanes<T>];
};

#if defined(__SSE2__)
template <class T>
void float_lanes(const T* row, std::int64_t& i, std::int64_t n, FloatLanes<T>& out) {
  if constexpr (std::is_same_v<T, float>) {
    __m128 lo0 = _mm_loadu_ps(out.lo), lo1 = _mm_loadu_ps(out.lo + 4);
    __m128 hi0 = _mm_loadu_ps(out.hi), hi1 = _mm_loadu_ps(out.hi + 4);
    __m128 nf0 = _mm_loadu_ps(out.nonfinite), nf1 = _mm_loadu_ps(out.nonfinite + 4);
    for (; i + 8 <= n; i += 8) {
      const __m128 a = _mm_loadu_ps(row + i), b = _mm_loadu_ps(row + i + 4);
      lo0 = _mm_min_ps(a, lo0);
      lo1 = _mm_min_ps(b, lo1);
      hi0 = _mm_max_ps(a, hi0);
      hi1 = _mm_max_ps(b, hi1);
      nf0 = _mm_add_ps(nf0, _mm_sub_ps(a, a));
      nf1 = _mm_add_ps(nf1, _mm_sub_ps(b, b));
    }
    _mm_storeu_ps(out.lo, lo0), _mm_storeu_ps(out.lo + 4, lo1);
    _mm_storeu_ps(out.hi, hi0), _mm_storeu_ps(out.hi + 4, hi1);
    _mm_storeu_ps(out.nonfinite, nf0), _mm_storeu_ps(out.nonfinite + 4, nf1);
  } else {
    __m128d lo0 = _mm_loadu_pd(out.lo), lo1 = _mm_loadu_pd(out.lo + 2);
    __m128d hi0 = _mm_loadu_pd(out.hi), hi1 = _mm_loadu_pd(out.hi + 2);
    __m128d nf0 = _mm_loadu_pd(out.nonfinite), nf1 = _mm_loadu_pd(out.nonfinite + 2);
    for (; i + 4 <= n; i += 4) {
      const __m128d a = _mm_loadu_pd(row + i), b = _mm_loadu_pd(row + i + 2);
      lo0 = _mm_min_pd(a, lo0);
      lo1 = _mm_min_pd(b, lo1);
      hi0 = _mm_max_pd(a, hi0);
      hi1 = _mm_max_pd(b, hi1);
      nf0 = _mm_add_pd(nf0, _mm_sub_pd(a, a));
      nf1 = _mm_add_pd(nf1, _mm_sub_pd(b, b));
    }
    _mm_storeu_pd(out.lo, lo0), _mm_storeu_pd(out.lo + 2, lo1);
    _mm_storeu_pd(out.hi, hi0), _mm_storeu_pd(out.hi + 2, hi1);
    _mm_storeu_pd(out.nonfinite, nf0), _mm_storeu_pd(out.nonfinite + 2, nf1);
  }
}
#else
template <class T>
void float_lanes(const T* row, std::int64_t& i, std::int64_t n, FloatLanes<T>& out) {
  constexpr int L = kLanes<T>;
  for (; i + L <= n; i += L)
    for (int l = 0; l < L; ++l) {
      const T v = row[i + l];
      out.lo[l] = v < out.lo[l] ? v : out.lo[l];
      out.hi[l] = v > out.hi[l] ? v : out.hi[l];
      out.nonfinite[l] += v - v;
    }
}
#endif

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
  T lo = start_lo, hi = start_hi, nonfinite = 0;
  T lo_l[L], hi_l[L];
  FloatLanes<T> fl;
  for (int l = 0; l < L; ++l) {
    lo_l[l] = fl.lo[l] = start_lo;
    hi_l[l] = fl.hi[l] = start_hi;
    fl.nonfinite[l] = 0;
  }
  for (std::int64_t r = row_begin; r != row_end; ++r) {
    const T* row = data + view.offset(0, r % ny, r / ny);
    std::int64_t i = 0;
    if (stride == 1) {
      if constexpr (floating) {
        float_lanes(row, i, n, fl);
      } else {
        for (; i + L <= n; i += L)
          for (int l = 0; l < L; ++l) {
            const T v = row[i + l];
            lo_l[l] = v < lo_l[l] ? v : lo_l[l];
            hi_l[l] = v > hi_l[l] ? v : hi_l[l];
          }
      }
    }
    for (; i < n; ++i) {
      const T v = row[i * stride];
      lo = v < lo ? v : lo;
      hi = v > hi ? v : hi;
      if constexpr (floating) nonfinite += v - v;
    }
  }
  for (int l = 0; l < L; ++l) {
    const T l_lo = floating ? fl.lo[l] : lo_l[l], l_hi = floating ? fl.hi[l] : hi_l[l];
    lo = l_lo < lo ? l_lo : lo;
    hi = l_hi > hi ? l_hi : hi;
    if constexpr (floating) nonfinite += fl.nonfinite[l];
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
  // Throws, counting the NaN and Inf samples and naming the first.
  if (!s.finite) check_finite(view, what);
  return bounds(s);
}

}  // namespace isotile
