// Sample classification shared by the CPU extractors (Marching Cubes, Dual Contouring): one
// inside bit per sample, so that every extractor sees the same inside/outside for every sample.
// Internal to core/; not part of the library's interface.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

#include "core/extract/scratch_vector.h"
#include "core/progress.h"
#include "core/volume/volume.h"

#if defined(__SSE4_1__)
#include <immintrin.h>
#endif

namespace isotile::detail {

using std::int64_t;
using std::uint64_t;

// The classification of every sample is packed into one bit per sample, 64 to a word, one run of
// words per grid row (fixed j, k). Crossed edges and mixed cells then fall out of word-wide XORs,
// so empty space costs a few instructions per 64 cells, and a vertex's index is a rank (popcount)
// in these masks: no per-edge index array is ever stored.
struct BitGrid {
  int64_t nx = 0, ny = 0, nz = 0;
  int64_t words = 0;             // per row
  ScratchVector<uint64_t> bits;  // classify() writes every word

  const uint64_t* row(int64_t j, int64_t k) const { return bits.data() + (k * ny + j) * words; }
};

// Bits [0, n) set for word w of a row holding n meaningful bits.
inline uint64_t valid_bits(int64_t w, int64_t n) {
  const int64_t left = n - w * 64;
  if (left >= 64) return ~uint64_t{0};
  if (left <= 0) return 0;
  return (uint64_t{1} << left) - 1;
}

// Samples compare as `value >= iso`. Each type compares against an equivalent threshold of its
// own type (integers: the smallest inside integer; float: iso rounded up to the next float), which
// gives exactly the answer of comparing in double without converting every sample, and lets 16
// samples be classified per SIMD instruction.
template <class T>
struct InsideTest {
  explicit InsideTest(double iso) {
    if constexpr (std::is_integral_v<T>) {
      const double t = std::ceil(iso);
      if (t <= static_cast<double>(std::numeric_limits<T>::min())) {
        all = true;
      } else if (t > static_cast<double>(std::numeric_limits<T>::max())) {
        none = true;
      } else {
        threshold = static_cast<T>(t);
      }
    } else if constexpr (std::is_same_v<T, float>) {
      float f = static_cast<float>(iso);
      if (static_cast<double>(f) < iso)
        f = std::nextafter(f, std::numeric_limits<float>::infinity());
      threshold = f;
    } else {
      threshold = iso;
    }
  }
  bool operator()(T v) const { return all || (!none && v >= threshold); }

  T threshold{};
  bool all = false, none = false;
};

// Inside bits of 64 contiguous samples.
template <class T>
uint64_t pack64(const T* src, const InsideTest<T>& inside) {
#if defined(__SSE4_1__)
  if constexpr (sizeof(T) == 1) {
    // Unsigned x >= t is max(x, t) == x; signed compares flip the sign bit first.
    const __m128i bias = _mm_set1_epi8(std::is_signed_v<T> ? 0 : static_cast<char>(0x80));
    const __m128i t = _mm_xor_si128(_mm_set1_epi8(static_cast<char>(inside.threshold)), bias);
    uint64_t m = 0;
    for (int b = 0; b < 64; b += 16) {
      const __m128i x =
          _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(src + b)), bias);
      const __m128i lt = _mm_cmpgt_epi8(t, x);  // t > x  <=>  x < t
      m |= static_cast<uint64_t>(~_mm_movemask_epi8(lt) & 0xffff) << b;
    }
    return m;
  } else if constexpr (sizeof(T) == 2) {
    const __m128i bias = _mm_set1_epi16(std::is_signed_v<T> ? 0 : static_cast<short>(0x8000));
    const __m128i t = _mm_xor_si128(_mm_set1_epi16(static_cast<short>(inside.threshold)), bias);
    uint64_t m = 0;
    for (int b = 0; b < 64; b += 16) {
      const __m128i x0 =
          _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(src + b)), bias);
      const __m128i x1 =
          _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(src + b + 8)), bias);
      const __m128i lt = _mm_packs_epi16(_mm_cmpgt_epi16(t, x0), _mm_cmpgt_epi16(t, x1));
      m |= static_cast<uint64_t>(~_mm_movemask_epi8(lt) & 0xffff) << b;
    }
    return m;
  } else if constexpr (std::is_same_v<T, float>) {
    const __m128 t = _mm_set1_ps(inside.threshold);
    uint64_t m = 0;
    for (int b = 0; b < 64; b += 4)
      m |= static_cast<uint64_t>(_mm_movemask_ps(_mm_cmpge_ps(_mm_loadu_ps(src + b), t))) << b;
    return m;
  }
#endif
  uint64_t m = 0;
  for (int b = 0; b < 64; ++b) m |= uint64_t{src[b] >= inside.threshold} << b;
  return m;
}

// With `progress`: advances the current stage by one per row, a z-slice at a time.
template <class T>
void classify(const VolumeView& view, double iso, BitGrid& grid, Progress* progress = nullptr) {
  const T* data = view.typed<T>();
  const InsideTest<T> inside(iso);
  const int64_t nx = grid.nx, words = grid.words, sx = view.strides[0];
  auto rows = [&](const auto& range) {
    for (int64_t r = range.begin(); r != range.end(); ++r) {
      const int64_t j = r % grid.ny, k = r / grid.ny;
      const T* src = data + view.offset(0, j, k);
      uint64_t* dst = grid.bits.data() + r * words;
      for (int64_t w = 0; w < words; ++w) {
        const int64_t i0 = w * 64, n = std::min<int64_t>(64, nx - i0);
        uint64_t m = 0;
        if (inside.all || inside.none) {
          m = inside.all ? valid_bits(0, n) : 0;
        } else if (sx == 1 && n == 64) {
          m = pack64(src + i0, inside);
        } else {
          for (int64_t b = 0; b < n; ++b) m |= uint64_t{inside(src[(i0 + b) * sx])} << b;
        }
        dst[w] = m;
      }
    }
  };
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, grid.ny * grid.nz),
                    for_units(progress, grid.ny, rows));
}

// Bits [lo, hi) of word w of a row.
inline uint64_t range_bits(int64_t w, int64_t lo, int64_t hi) {
  return valid_bits(w, hi) & ~valid_bits(w, lo);
}

// Crossed edges owned by one row of grid points, one entry per 64 points: a mask per axis and the
// number of crossed edges (all axes) in earlier words. Vertices are numbered in key order, by point
// and then axis, so a vertex's rank in its row is the prefix plus popcounts.
struct EdgeWord {
  uint64_t mask[3];
  std::uint32_t prefix;
};

// Rank of the edge of axis a at x index i among its row's vertices.
inline std::uint32_t edge_rank(const EdgeWord* row, int a, int64_t i) {
  const EdgeWord& wd = row[i >> 6];
  const int b = static_cast<int>(i & 63);
  const uint64_t below = (uint64_t{1} << b) - 1;
  std::uint32_t r = wd.prefix;
  for (int c = 0; c < 3; ++c) {
    r += static_cast<std::uint32_t>(std::popcount(wd.mask[c] & below));
    if (c < a) r += static_cast<std::uint32_t>((wd.mask[c] >> b) & 1);
  }
  return r;
}

// Words of bit i+1 aligned to bit i ("the sample to the right").
inline uint64_t shifted(const uint64_t* row, int64_t w, int64_t words) {
  const uint64_t hi = w + 1 < words ? row[w + 1] << 63 : 0;
  return (row[w] >> 1) | hi;
}

// One 64-cell word of a cell row (j, k): for each of its four point rows (j,k), (j+1,k), (j,k+1),
// (j+1,k+1), the inside bits of the cells' lower x corners (lo) and upper x corners (hi).
struct CellWord {
  uint64_t lo[4], hi[4];
  uint64_t mixed;  // cells whose eight corners are not all on one side

  CellWord(const uint64_t* const rows[4], int64_t w, int64_t words, int64_t nx) {
    uint64_t any = 0, all = ~uint64_t{0};
    for (int r = 0; r < 4; ++r) {
      lo[r] = rows[r][w];
      hi[r] = shifted(rows[r], w, words);
      any |= lo[r] | hi[r];
      all &= lo[r] & hi[r];
    }
    mixed = any & ~all & valid_bits(w, nx - 1);
  }

  // Case of the cell at bit b: corner x + 2y + 4z.
  int cell_case(int b) const {
    return static_cast<int>(((lo[0] >> b) & 1) | ((hi[0] >> b) & 1) << 1 | ((lo[1] >> b) & 1) << 2 |
                            ((hi[1] >> b) & 1) << 3 | ((lo[2] >> b) & 1) << 4 |
                            ((hi[2] >> b) & 1) << 5 | ((lo[3] >> b) & 1) << 6 |
                            ((hi[3] >> b) & 1) << 7);
  }
};

}  // namespace isotile::detail
