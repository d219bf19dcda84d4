#include "core/extract/cell_ranges.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/errors.h"

namespace isotile {
namespace {

// The largest (max - min) of the cells from `corner` on: two along each axis whose bit is set in
// P, else one; the ranges subtracted in double, starting from 0.
template <class T, int P>
inline double largest_cell_range(const T* corner, const Index3& stride) {
  constexpr int n0 = (P & 1) ? 3 : 2, n1 = (P & 2) ? 3 : 2, n2 = (P & 4) ? 3 : 2;
  T s[n2][n1][n0];
  for (int k = 0; k < n2; ++k)
    for (int j = 0; j < n1; ++j)
      for (int i = 0; i < n0; ++i)
        s[k][j][i] = corner[k * stride[2] + j * stride[1] + i * stride[0]];
  double best = 0;
  for (int k = 0; k + 1 < n2; ++k)
    for (int j = 0; j + 1 < n1; ++j)
      for (int i = 0; i + 1 < n0; ++i) {
        T mn = s[k][j][i], mx = mn;
        for (int c = 1; c < 8; ++c) {
          const T x = s[k + (c >> 2)][j + ((c >> 1) & 1)][i + (c & 1)];
          mn = std::min(mn, x);
          mx = std::max(mx, x);
        }
        best = std::max(best, static_cast<double>(mx) - static_cast<double>(mn));
      }
  return best;
}

// The largest (max - min) of the cells [lo, hi] (inclusive, per axis) that lie inside `mask`.
template <class T>
double largest_masked_range(const VolumeView& view, const VolumeView& mask,
                            const std::int64_t lo[3], const std::int64_t hi[3]) {
  const T* data = view.typed<T>();
  const std::uint8_t* set = mask.typed<std::uint8_t>();
  double best = 0;
  for (std::int64_t k = lo[2]; k <= hi[2]; ++k)
    for (std::int64_t j = lo[1]; j <= hi[1]; ++j)
      for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
        bool inside = true;
        T mn{}, mx{};
        for (int c = 0; c < 8 && inside; ++c) {
          const std::int64_t x = i + (c & 1), y = j + ((c >> 1) & 1), z = k + (c >> 2);
          inside = set[mask.offset(x, y, z)] != 0;
          const T v = data[view.offset(x, y, z)];
          mn = c == 0 ? v : std::min(mn, v);
          mx = c == 0 ? v : std::max(mx, v);
        }
        if (inside) best = std::max(best, static_cast<double>(mx) - static_cast<double>(mn));
      }
  return best;
}

template <class T>
std::vector<float> typed_ranges(const VolumeView& view, const Mesh& mesh, const VolumeView* mask) {
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
          if (mask) {
            out[v] = static_cast<float>(largest_masked_range<T>(view, *mask, lo, hi));
            continue;
          }
          // Which axes hold two cells picks one of eight fixed-size loops (an MC vertex has two,
          // on the two grid planes through its edge): unrolled, where loops whose trip counts
          // change from vertex to vertex mispredicted several times per vertex. A switch, where
          // each loop is inlined: a table of the eight instantiations called through a pointer
          // took a fifth longer (bonsai, one thread: 19.3 against 15.9 ms).
          const T* corner = data + view.offset(lo[0], lo[1], lo[2]);
          const int pattern = static_cast<int>(hi[0] != lo[0]) |
                              static_cast<int>(hi[1] != lo[1]) << 1 |
                              static_cast<int>(hi[2] != lo[2]) << 2;
          double best = 0;
          switch (pattern) {
            case 0:
              best = largest_cell_range<T, 0>(corner, view.strides);
              break;
            case 1:
              best = largest_cell_range<T, 1>(corner, view.strides);
              break;
            case 2:
              best = largest_cell_range<T, 2>(corner, view.strides);
              break;
            case 3:
              best = largest_cell_range<T, 3>(corner, view.strides);
              break;
            case 4:
              best = largest_cell_range<T, 4>(corner, view.strides);
              break;
            case 5:
              best = largest_cell_range<T, 5>(corner, view.strides);
              break;
            case 6:
              best = largest_cell_range<T, 6>(corner, view.strides);
              break;
            default:
              best = largest_cell_range<T, 7>(corner, view.strides);
              break;
          }
          out[v] = static_cast<float>(best);
        }
      });
  return out;
}

}  // namespace

std::vector<float> vertex_cell_ranges(const VolumeView& view, const Mesh& mesh,
                                      const VolumeView* mask) {
  if (view.dims[0] < 2 || view.dims[1] < 2 || view.dims[2] < 2)
    return std::vector<float>(mesh.positions.size(), 0.0f);
  if (mask && (mask->type != ScalarType::UInt8 || mask->dims != view.dims))
    throw InputError("the mask must be uint8 samples of the volume's dims");
  return visit_scalar(view.type,
                      [&](auto tag) { return typed_ranges<decltype(tag)>(view, mesh, mask); });
}

}  // namespace isotile
