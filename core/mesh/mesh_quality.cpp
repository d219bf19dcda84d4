#include "core/mesh/mesh_quality.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace isotile {

double radius_ratio(const Vec3f& a, const Vec3f& b, const Vec3f& c) {
  auto length = [](const Vec3f& p, const Vec3f& q) {
    const double dx = double{p[0]} - q[0], dy = double{p[1]} - q[1], dz = double{p[2]} - q[2];
    return std::sqrt(dx * dx + dy * dy + dz * dz);
  };
  return radius_ratio_of_lengths(length(b, c), length(c, a), length(a, b));
}

namespace {

// Fixed chunking is what makes the floating-point sum independent of the thread count.
constexpr std::size_t kChunk = 1 << 14;

struct ChunkStats {
  double sum = 0;
  double min = 1, max = 0;
  std::uint64_t degenerate = 0;
  std::array<std::uint64_t, 20> histogram{};
};

// Quality of a quad split along diagonal 0-2 or 1-3, whichever leaves the better worst triangle
// (0-2 on a tie).
std::array<double, 2> quad_quality(const Mesh& mesh, const Quad& q) {
  const auto& p = mesh.positions;
  const double a0 = radius_ratio(p[q[0]], p[q[1]], p[q[2]]);
  const double a1 = radius_ratio(p[q[0]], p[q[2]], p[q[3]]);
  const double b0 = radius_ratio(p[q[0]], p[q[1]], p[q[3]]);
  const double b1 = radius_ratio(p[q[1]], p[q[2]], p[q[3]]);
  if (std::min(b0, b1) > std::min(a0, a1)) return {b0, b1};
  return {a0, a1};
}

}  // namespace

QualityStats triangle_quality(const Mesh& mesh) {
  QualityStats stats;
  const std::size_t ntri = mesh.triangles.size();
  const std::size_t n = ntri + 2 * mesh.quads.size();
  stats.triangles = n;
  if (n == 0) return stats;

  std::vector<double> q(n);
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<ChunkStats> partial(chunks);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, chunks, 1),
      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t c = r.begin(); c < r.end(); ++c) {
          const std::size_t begin = c * kChunk, end = std::min(n, begin + kChunk);
          for (std::size_t i = begin; i < end; ++i) {
            if (i < ntri) {
              const Tri& t = mesh.triangles[i];
              q[i] = radius_ratio(mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]);
              continue;
            }
            // A chunk border may split a quad's pair; each side then recomputes the quad.
            const auto pair = quad_quality(mesh, mesh.quads[(i - ntri) / 2]);
            if ((i - ntri) % 2 == 1) {
              q[i] = pair[1];
              continue;
            }
            q[i] = pair[0];
            if (i + 1 < end) q[++i] = pair[1];
          }
          ChunkStats& s = partial[c];
          for (std::size_t i = begin; i < end; ++i) {
            const double v = q[i];
            s.sum += v;
            s.min = std::min(s.min, v);
            s.max = std::max(s.max, v);
            if (v < 1e-6) ++s.degenerate;
            s.histogram[std::min<std::size_t>(static_cast<std::size_t>(v * 20), 19)]++;
          }
        }
      },
      tbb::simple_partitioner());

  double sum = 0;
  stats.min = 1;
  stats.max = 0;
  for (const ChunkStats& s : partial) {
    sum += s.sum;
    stats.min = std::min(stats.min, s.min);
    stats.max = std::max(stats.max, s.max);
    stats.degenerate += s.degenerate;
    for (std::size_t b = 0; b < s.histogram.size(); ++b) stats.histogram[b] += s.histogram[b];
  }
  stats.mean = sum / static_cast<double>(n);

  // The value at a rank is the same whatever algorithm finds it; successive nth_element calls
  // on the upper part keep the earlier ranks in place.
  // floor(f * (n - 1)) in integers, free of rounding in f.
  const std::size_t r001 = (n - 1) / 1000, r01 = (n - 1) / 100, r50 = (n - 1) / 2;
  std::nth_element(q.begin(), q.begin() + r001, q.end());
  stats.q001 = q[r001];
  std::nth_element(q.begin() + r001, q.begin() + r01, q.end());
  stats.q01 = q[r01];
  std::nth_element(q.begin() + r01, q.begin() + r50, q.end());
  stats.median = q[r50];
  return stats;
}

}  // namespace isotile
