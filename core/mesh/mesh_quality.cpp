#include "core/mesh/mesh_quality.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/errors.h"

namespace isotile {

namespace {

// Inlined into the measure's loops (a call per triangle costs as much as the arithmetic).
inline double radius_ratio_inline(const Vec3f& a, const Vec3f& b, const Vec3f& c) {
  auto length = [](const Vec3f& p, const Vec3f& q) {
    const double dx = double{p[0]} - q[0], dy = double{p[1]} - q[1], dz = double{p[2]} - q[2];
    return std::sqrt(dx * dx + dy * dy + dz * dz);
  };
  return radius_ratio_of_lengths(length(b, c), length(c, a), length(a, b));
}

}  // namespace

double radius_ratio(const Vec3f& a, const Vec3f& b, const Vec3f& c) {
  return radius_ratio_inline(a, b, c);
}

namespace {

// Work is split in fixed chunks, each with its own partial statistics.
constexpr std::size_t kChunk = 1 << 14;

struct ChunkStats {
  RatioSum sum;
  double min = 1, max = 0;
  std::uint64_t degenerate = 0;
  std::array<std::uint64_t, 20> histogram{};
};

inline QuadSplit split_quad_inline(const std::vector<Vec3f>& p, const Quad& q) {
  const double a0 = radius_ratio_inline(p[q[0]], p[q[1]], p[q[2]]);
  const double a1 = radius_ratio_inline(p[q[0]], p[q[2]], p[q[3]]);
  const double b0 = radius_ratio_inline(p[q[0]], p[q[1]], p[q[3]]);
  const double b1 = radius_ratio_inline(p[q[1]], p[q[2]], p[q[3]]);
  if (std::min(b0, b1) > std::min(a0, a1))
    return {{Tri{q[0], q[1], q[3]}, Tri{q[1], q[2], q[3]}}, {b0, b1}};
  return {{Tri{q[0], q[1], q[2]}, Tri{q[0], q[2], q[3]}}, {a0, a1}};
}

// Calls f(v) for the quality of triangles [begin, end) in order (quads as their two triangles).
template <class F>
void for_each_quality(const Mesh& mesh, std::size_t begin, std::size_t end, F&& f) {
  const std::size_t ntri = mesh.triangles.size();
  for (std::size_t i = begin; i < end; ++i) {
    if (i < ntri) {
      const Tri& t = mesh.triangles[i];
      f(radius_ratio_inline(mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]));
      continue;
    }
    // A chunk border may split a quad's pair; each side then recomputes the quad.
    const auto pair = split_quad_inline(mesh.positions, mesh.quads[(i - ntri) / 2]).quality;
    if ((i - ntri) % 2 == 1) {
      f(pair[1]);
      continue;
    }
    f(pair[0]);
    if (i + 1 < end) {
      f(pair[1]);
      ++i;
    }
  }
}

// Exact quantiles without keeping every value: a fine histogram finds the bin that holds each
// rank, a second pass collects only the values of those bins, and the rank is taken among them.
// Values lie in [0, 1], where a double's bits order like the double; a bin is one of 2^10 slices
// of an octave, over the 32 octaves below 1, all smaller values (0 included) in bin 0. The first
// pass keeps each triangle's bin (2 bytes a triangle), so that the second one computes again only
// the values it keeps.
constexpr int kOctaves = 32;
constexpr int kSliceBits = 10;
constexpr std::size_t kFineBins = 1 + ((kOctaves + 1) << kSliceBits);

std::size_t fine_bin(double v) {
  const auto bits = std::bit_cast<std::uint64_t>(v);
  const int exponent = static_cast<int>(bits >> 52);
  const int lowest = 1023 - kOctaves;
  if (exponent < lowest) return 0;
  return 1 + (static_cast<std::size_t>(exponent - lowest) << kSliceBits) +
         static_cast<std::size_t>((bits >> (52 - kSliceBits)) & ((1u << kSliceBits) - 1));
}

using FineHistogram = std::vector<std::uint64_t>;
using FineBin = std::uint16_t;
static_assert(kFineBins <= std::numeric_limits<FineBin>::max() + std::size_t{1});

}  // namespace

QuadSplit split_quad(const std::vector<Vec3f>& positions, const Quad& q) {
  for (const std::uint32_t v : q)
    if (v >= positions.size())
      throw InputError("quad references vertex " + std::to_string(v) + " but there are " +
                       std::to_string(positions.size()) + " vertices");
  return split_quad_inline(positions, q);
}

QualityStats triangle_quality(const Mesh& mesh) {
  // A mesh from outside (the library's caller) may hold any index: read past the positions, it
  // was a crash here, an InputError in every other measure.
  check_face_indices(mesh);
  QualityStats stats;
  const std::size_t n = mesh.triangles.size() + 2 * mesh.quads.size();
  stats.triangles = n;
  if (n == 0) return stats;

  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<ChunkStats> partial(chunks);
  // Integer counts: their sum is the same however chunks are spread over threads.
  tbb::enumerable_thread_specific<FineHistogram> fine_local(
      [] { return FineHistogram(kFineBins, 0); });
  auto bins = std::make_unique_for_overwrite<FineBin[]>(n);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, chunks, 1),
      [&](const tbb::blocked_range<std::size_t>& r) {
        FineHistogram& fine = fine_local.local();
        for (std::size_t c = r.begin(); c < r.end(); ++c) {
          ChunkStats& s = partial[c];
          const std::size_t begin = c * kChunk, end = std::min(n, begin + kChunk);
          std::size_t i = begin;
          for_each_quality(mesh, begin, end, [&](double v) {
            s.sum.add(v);
            s.min = std::min(s.min, v);
            s.max = std::max(s.max, v);
            if (degenerate_ratio(v)) ++s.degenerate;
            s.histogram[histogram_bin(v)]++;
            const std::size_t b = fine_bin(v);
            ++fine[b];
            bins[i++] = static_cast<FineBin>(b);
          });
        }
      },
      tbb::simple_partitioner());

  RatioSum sum;
  stats.min = 1;
  stats.max = 0;
  for (const ChunkStats& s : partial) {
    sum.add(s.sum);
    stats.min = std::min(stats.min, s.min);
    stats.max = std::max(stats.max, s.max);
    stats.degenerate += s.degenerate;
    for (std::size_t b = 0; b < s.histogram.size(); ++b) stats.histogram[b] += s.histogram[b];
  }
  stats.mean = sum.value() / static_cast<double>(n);

  FineHistogram fine(kFineBins, 0);
  for (const FineHistogram& h : fine_local) {
    for (std::size_t b = 0; b < kFineBins; ++b) fine[b] += h[b];
  }
  // floor(f * (n - 1)) in integers, free of rounding in f.
  const std::array<std::size_t, 3> ranks = {(n - 1) / 1000, (n - 1) / 100, (n - 1) / 2};
  // The bin holding each rank, and how many values lie in the bins below it.
  std::array<std::size_t, 3> bin{}, below{};
  {
    std::size_t b = 0, seen = 0;
    for (std::size_t k = 0; k < ranks.size(); ++k) {
      while (seen + fine[b] <= ranks[k]) seen += fine[b++];
      bin[k] = b;
      below[k] = seen;
    }
  }
  tbb::enumerable_thread_specific<std::array<std::vector<double>, 3>> picked_local;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, chunks, 1),
      [&](const tbb::blocked_range<std::size_t>& r) {
        auto& picked = picked_local.local();
        for (std::size_t c = r.begin(); c < r.end(); ++c) {
          const std::size_t begin = c * kChunk, end = std::min(n, begin + kChunk);
          for (std::size_t i = begin; i < end; ++i) {
            const std::size_t b = bins[i];
            // Ranks that share a bin share its values: kept once, under the first.
            for (std::size_t k = 0; k < bin.size(); ++k) {
              if (b == bin[k]) {
                for_each_quality(mesh, i, i + 1, [&](double v) { picked[k].push_back(v); });
                break;
              }
            }
          }
        }
      },
      tbb::simple_partitioner());
  std::array<double, 3> value{};
  for (std::size_t k = 0; k < ranks.size(); ++k) {
    std::size_t owner = 0;
    while (bin[owner] != bin[k]) ++owner;
    // The value at a rank is the same in whatever order the values were collected.
    std::vector<double> values;
    for (const auto& picked : picked_local) {
      values.insert(values.end(), picked[owner].begin(), picked[owner].end());
    }
    const auto nth = values.begin() + static_cast<std::ptrdiff_t>(ranks[k] - below[k]);
    std::nth_element(values.begin(), nth, values.end());
    value[k] = *nth;
  }
  stats.q001 = value[0];
  stats.q01 = value[1];
  stats.median = value[2];
  return stats;
}

}  // namespace isotile
