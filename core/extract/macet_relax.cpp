#include "core/extract/macet_relax.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/volume/scalar_type.h"

namespace isotile::detail {

namespace {

template <class T>
void relax_typed(const VolumeView& view, double iso, double relax, ScratchVector<double>& out) {
  const T* data = view.typed<T>();
  const std::int64_t nx = view.dims[0], ny = view.dims[1], nz = view.dims[2];
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, ny * nz), [&](const auto& range) {
    for (std::int64_t r = range.begin(); r != range.end(); ++r) {
      const std::int64_t j = r % ny, k = r / ny;
      for (std::int64_t i = 0; i < nx; ++i) {
        const std::int64_t p[3] = {i, j, k};
        const double s = static_cast<double>(data[view.offset(i, j, k)]);
        double& result = out[static_cast<std::size_t>(i + nx * r)];
        result = s;
        const double f = s - iso;
        const bool in = f >= 0;
        // Quick rejection (nearly every sample): pinned needs an axis whose two neighbours are
        // both in the view and both on the other side.
        const T* c = data + view.offset(i, j, k);
        bool candidate = false;
        for (int a = 0; a < 3 && !candidate; ++a)
          candidate = p[a] > 0 && p[a] + 1 < view.dims[a] &&
                      (static_cast<double>(c[-view.strides[a]]) >= iso) != in &&
                      (static_cast<double>(c[view.strides[a]]) >= iso) != in;
        if (!candidate) continue;
        const double af = std::abs(f);
        bool complete = true, pinned = false;
        double need = 0, limit = INFINITY;
        for (int a = 0; a < 3 && complete; ++a) {
          bool near[2] = {false, false};
          for (int side = 0; side < 2; ++side) {
            std::int64_t q[3] = {p[0], p[1], p[2]};
            q[a] += side ? 1 : -1;
            const std::int64_t global = view.box.lo[a] + q[a];
            if (global < 0 || global >= view.global_dims[a]) continue;  // the volume ends
            if (q[a] < 0 || q[a] >= view.dims[a]) {
              complete = false;  // the volume goes on beyond the view
              break;
            }
            const double g = static_cast<double>(data[view.offset(q[0], q[1], q[2])]) - iso;
            if ((g >= 0) == in) continue;
            const double ag = std::abs(g);
            const double t = af / (af + ag);  // the crossing, in edge lengths from this sample
            // The value that puts this crossing at `relax`, and the one that moves it by relax.
            if (t < relax) {
              near[side] = true;
              need = std::max(need, relax * ag / (1 - relax));
            }
            if (t + relax < 1) limit = std::min(limit, (t + relax) * ag / (1 - t - relax));
          }
          pinned = pinned || (near[0] && near[1]);
        }
        if (!complete || !pinned) continue;
        const double moved = std::min(need, limit);
        const double relaxed = iso + (in ? moved : -moved);
        // Rounding may not flip the side (a tiny move next to a huge isovalue).
        if (moved > af && (relaxed >= iso) == in) result = relaxed;
      }
    }
  });
}

}  // namespace

ScratchVector<double> relax_pinned_samples(const VolumeView& view, double iso, double relax) {
  // Every entry is written by the parallel pass, which also first-touches the pages.
  ScratchVector<double> out(static_cast<std::size_t>(view.sample_count()));
  visit_scalar(view.type, [&](auto tag) { relax_typed<decltype(tag)>(view, iso, relax, out); });
  return out;
}

}  // namespace isotile::detail
