#include "core/mesh/field_distance.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <vector>

namespace isotile {

FieldDistance field_distance(const FieldSpec& spec, const Mesh& mesh, const Vec3d& origin,
                             const Vec3d& spacing) {
  const std::size_t n = mesh.positions.size();
  if (n == 0) return {};
  constexpr std::size_t kChunk = 4096;
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<double> sum(chunks), max(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    double s = 0, m = 0;
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      Vec3d p;
      for (int a = 0; a < 3; ++a)
        p[a] = (static_cast<double>(mesh.positions[i][a]) - origin[a]) / spacing[a];
      const double d = distance_voxels(spec, p);
      s += d;
      m = std::max(m, d);
    }
    sum[c] = s;
    max[c] = m;
  });
  FieldDistance out;
  for (std::size_t c = 0; c < chunks; ++c) {
    out.mean += sum[c];
    out.max = std::max(out.max, max[c]);
  }
  out.mean /= static_cast<double>(n);
  return out;
}

}  // namespace isotile
