#include "core/extract/cell_ranges.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace isotile {
namespace {

template <class T>
std::vector<float> typed_ranges(const VolumeView& view, const Mesh& mesh) {
  const T* data = view.typed<T>();
  const std::size_t n = mesh.positions.size();
  std::vector<float> out(n);
  const Vec3d inv{1 / view.spacing[0], 1 / view.spacing[1], 1 / view.spacing[2]};
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, n, 4096), [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t v = r.begin(); v != r.end(); ++v) {
          // The cells along each axis whose closed extent holds the vertex: two where it lies on a
          // grid plane (within float rounding of the position), else one.
          std::int64_t lo[3], hi[3];
          for (int a = 0; a < 3; ++a) {
            const double g = (static_cast<double>(mesh.positions[v][a]) - view.origin[a]) * inv[a] -
                             static_cast<double>(view.box.lo[a]);
            const double k = std::floor(g + 0.5);  // nearest grid plane (std::round is a libm call)
            const std::int64_t last = view.dims[a] - 2;
            if (std::abs(g - k) < 1e-4) {
              lo[a] = static_cast<std::int64_t>(k) - 1;
              hi[a] = static_cast<std::int64_t>(k);
            } else {
              lo[a] = hi[a] = static_cast<std::int64_t>(std::floor(g));
            }
            lo[a] = std::clamp<std::int64_t>(lo[a], 0, last);
            hi[a] = std::clamp<std::int64_t>(hi[a], 0, last);
          }
          // The samples of those cells, read once (at most 3 x 3 x 3), then each cell's range.
          const std::int64_t n[3] = {hi[0] - lo[0] + 2, hi[1] - lo[1] + 2, hi[2] - lo[2] + 2};
          T s[3][3][3];
          for (std::int64_t k = 0; k < n[2]; ++k)
            for (std::int64_t j = 0; j < n[1]; ++j) {
              const T* row = data + view.offset(lo[0], lo[1] + j, lo[2] + k);
              for (std::int64_t i = 0; i < n[0]; ++i) s[k][j][i] = row[i * view.strides[0]];
            }
          double best = 0;
          for (std::int64_t k = 0; k + 1 < n[2]; ++k)
            for (std::int64_t j = 0; j + 1 < n[1]; ++j)
              for (std::int64_t i = 0; i + 1 < n[0]; ++i) {
                T mn = s[k][j][i], mx = mn;
                for (int c = 1; c < 8; ++c) {
                  const T x = s[k + (c >> 2)][j + ((c >> 1) & 1)][i + (c & 1)];
                  mn = std::min(mn, x);
                  mx = std::max(mx, x);
                }
                best = std::max(best, static_cast<double>(mx) - static_cast<double>(mn));
              }
          out[v] = static_cast<float>(best);
        }
      });
  return out;
}

}  // namespace

std::vector<float> vertex_cell_ranges(const VolumeView& view, const Mesh& mesh) {
  if (view.dims[0] < 2 || view.dims[1] < 2 || view.dims[2] < 2)
    return std::vector<float>(mesh.positions.size(), 0.0f);
  return visit_scalar(view.type, [&](auto tag) { return typed_ranges<decltype(tag)>(view, mesh); });
}

}  // namespace isotile
