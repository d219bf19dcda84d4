#include "core/volume/volume.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "core/errors.h"

namespace isotile {

double VolumeView::value(std::int64_t i, std::int64_t j, std::int64_t k) const {
  return visit_scalar(type, [&](auto tag) {
    using T = decltype(tag);
    return static_cast<double>(typed<T>()[offset(i, j, k)]);
  });
}

VolumeView dense_view(const void* data, ScalarType type, Index3 dims, Vec3d spacing, Vec3d origin) {
  VolumeView v;
  v.data = data;
  v.type = type;
  v.dims = dims;
  v.strides = {1, dims[0], dims[0] * dims[1]};
  v.spacing = spacing;
  v.origin = origin;
  v.box = {{0, 0, 0}, dims};
  v.global_dims = dims;
  return v;
}

VolumeView subview(const VolumeView& view, const Box3& local) {
  VolumeView v = view;
  Index3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::clamp<std::int64_t>(local.lo[a], 0, view.dims[a]);
    hi[a] = std::clamp<std::int64_t>(local.hi[a], lo[a], view.dims[a]);
    v.dims[a] = hi[a] - lo[a];
    v.box.lo[a] = view.box.lo[a] + lo[a];
    v.box.hi[a] = view.box.lo[a] + hi[a];
  }
  v.data = static_cast<const std::byte*>(view.data) +
           view.offset(lo[0], lo[1], lo[2]) * static_cast<std::int64_t>(scalar_size(view.type));
  return v;
}

Box3 local_cell_box(const VolumeView& view, const Box3& global_cells, int halo) {
  Box3 local;
  if (global_cells.empty()) {
    for (int a = 0; a < 3; ++a) local.hi[a] = std::max<std::int64_t>(view.dims[a] - 1, 0);
    return local;
  }
  for (int a = 0; a < 3; ++a) {
    const std::int64_t lo = std::max<std::int64_t>(global_cells.lo[a], 0);
    const std::int64_t hi = std::min<std::int64_t>(global_cells.hi[a], view.global_dims[a] - 1);
    // Samples needed: [lo - halo, hi + halo], clipped to the volume.
    const std::int64_t need_lo = std::max<std::int64_t>(lo - halo, 0);
    const std::int64_t need_hi = std::min<std::int64_t>(hi + halo, view.global_dims[a] - 1);
    if (lo >= hi || need_lo < view.box.lo[a] || need_hi >= view.box.hi[a])
      throw InputError("the view (samples " + std::to_string(view.box.lo[a]) + ".." +
                       std::to_string(view.box.hi[a] - 1) + " along axis " + std::to_string(a) +
                       ") does not hold cells " + std::to_string(global_cells.lo[a]) + ".." +
                       std::to_string(global_cells.hi[a] - 1) + " with a halo of " +
                       std::to_string(halo) + " samples");
    local.lo[a] = lo - view.box.lo[a];
    local.hi[a] = hi - view.box.lo[a];
  }
  return local;
}

namespace {

// The distance from float32 `m` (> 0) to the next float32 up: the step of a position there.
double float_step(double m) {
  const float f = static_cast<float>(m);
  return static_cast<double>(std::nextafter(f, std::numeric_limits<float>::infinity())) -
         static_cast<double>(f);
}

std::string triple_text(const Vec3d& v) {
  return std::to_string(v[0]) + "," + std::to_string(v[1]) + "," + std::to_string(v[2]);
}

// The world frame's part of check_grid_geometry().
void check_world_frame(const WorldFrame& world, const std::string& what) {
  for (double o : world.origin)
    if (!std::isfinite(o))
      throw InputError(what + ": the world origin is not finite: " + triple_text(world.origin));
  const Mat3& d = world.direction;
  for (double x : d)
    if (!std::isfinite(x)) throw InputError(what + ": the direction cosines are not finite");
  const double det = d[0] * (d[4] * d[8] - d[5] * d[7]) - d[1] * (d[3] * d[8] - d[5] * d[6]) +
                     d[2] * (d[3] * d[7] - d[4] * d[6]);
  if (!(std::abs(det) > 1e-6))
    throw InputError(what + ": the direction matrix is singular (determinant " +
                     std::to_string(det) + "): its axes do not span space");
}

}  // namespace

PositionResolution position_resolution(const Index3& dims, const Vec3d& spacing,
                                       const Vec3d& origin,
                                       const std::optional<WorldFrame>& world) {
  PositionResolution r;
  r.steps = std::numeric_limits<double>::infinity();
  // One frame's positions, each coordinate on its own: its largest magnitude over the grid's
  // corners (positions are affine in the sample index, so the corners bound them) against the
  // widest extent of a cell along it (a cell's own width in the grid frame).
  auto frame = [&](const Vec3d& base, const Mat3& d) {
    for (int row = 0; row < 3; ++row) {
      double largest = 0, cell = 0;
      for (int corner = 0; corner < 8; ++corner) {
        double x = base[row];
        for (int c = 0; c < 3; ++c)
          if (corner >> c & 1)
            x += d[3 * row + c] * spacing[c] *
                 static_cast<double>(std::max<std::int64_t>(dims[c] - 1, 0));
        largest = std::max(largest, std::abs(x));
      }
      for (int c = 0; c < 3; ++c) cell = std::max(cell, std::abs(d[3 * row + c]) * spacing[c]);
      r.largest = std::max(r.largest, largest);
      if (!(largest <= std::numeric_limits<float>::max())) {
        r.steps = 0;
        continue;
      }
      const double step = float_step(largest);
      if (cell / step < r.steps) {
        r.steps = cell / step;
        r.at = largest;
        r.step = step;
        r.cell = cell;
      }
    }
  };
  // Extractors write origin + spacing * index as float32; a world frame maps those floats.
  frame(origin, kIdentity3);
  if (world) frame(world->origin, world->direction);
  return r;
}

void warn_coarse_positions(const Index3& dims, const Vec3d& spacing, const Vec3d& origin,
                           const std::optional<WorldFrame>& world, const Warn& warn) {
  const PositionResolution r = position_resolution(dims, spacing, origin, world);
  if (!(r.steps < kFewPositionSteps)) return;
  say_warning(
      warn,
      "positions are float32: at the grid's coordinates of up to " + short_number(r.at) +
          " a float32 steps by " + short_number(r.step) + ", against cells " +
          short_number(r.cell) + " wide, so vertices snap to a lattice of about " +
          std::to_string(static_cast<long long>(r.steps)) +
          " steps per cell, which makes thin and degenerate triangles; a grid nearer 0 (the CLI's "
          "--origin) keeps full precision");
}

void check_grid_geometry(const Index3& dims, const Vec3d& spacing, const Vec3d& origin,
                         const std::optional<WorldFrame>& world, const std::string& what) {
  for (double s : spacing)
    if (!(std::isfinite(s) && s > 0))
      throw InputError(what + ": the spacing must be finite and positive, got " +
                       triple_text(spacing));
  for (double o : origin)
    if (!std::isfinite(o))
      throw InputError(what + ": the origin is not finite: " + triple_text(origin));
  if (world) check_world_frame(*world, what);
  check_position_range(dims, spacing, origin, world, what);
}

void check_position_range(const Index3& dims, const Vec3d& spacing, const Vec3d& origin,
                          const std::optional<WorldFrame>& world, const std::string& what) {
  const PositionResolution r = position_resolution(dims, spacing, origin, world);
  if (r.largest > std::numeric_limits<float>::max())
    throw InputError(what + ": the grid's coordinates reach " + short_number(r.largest) +
                     ", beyond the largest float32 (3.40282e+38), in which positions are written");
  if (r.steps < 1)
    throw InputError(what + ": the grid's cells, " + short_number(r.cell) +
                     " wide, are narrower than a float32 step (" + short_number(r.step) +
                     ") at its coordinates of up to " + short_number(r.at) +
                     ", in which positions are written: the mesh would collapse");
}

std::size_t checked_volume_bytes(ScalarType type, const Index3& dims) {
  for (int a = 0; a < 3; ++a)
    if (dims[a] <= 0)
      throw InputError("volume dimensions must be positive, got " + std::to_string(dims[0]) + "x" +
                       std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
  constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
  std::int64_t n = 1;
  for (int a = 0; a < 3; ++a) {
    if (n > kMax / dims[a])
      throw CapacityError("volume dimensions " + std::to_string(dims[0]) + "x" +
                          std::to_string(dims[1]) + "x" + std::to_string(dims[2]) +
                          " overflow a 64-bit sample count");
    n *= dims[a];
  }
  const auto size = static_cast<std::int64_t>(scalar_size(type));
  if (n > kMax / size)
    throw CapacityError("volume of " + std::to_string(n) +
                        " samples overflows a 64-bit byte count");
  return static_cast<std::size_t>(n * size);
}

Volume::Volume(ScalarType type, Index3 dims, Vec3d spacing, Vec3d origin)
    : bytes_(checked_volume_bytes(type, dims)),
      type_(type),
      dims_(dims),
      spacing_(spacing),
      origin_(origin) {
  try {
    data_ = std::make_unique_for_overwrite<std::byte[]>(bytes_);
  } catch (const std::bad_alloc&) {
    throw CapacityError("cannot allocate " + std::to_string(bytes_ >> 20) +
                        " MiB for a volume of " + std::to_string(dims[0]) + "x" +
                        std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " " +
                        std::string(scalar_name(type)) +
                        ": too large to read whole; --memory SIZE extracts it brick by brick");
  }
}

VolumeView Volume::view() const {
  VolumeView v = dense_view(data_.get(), type_, dims_, spacing_, origin_);
  v.world = world_;
  return v;
}

}  // namespace isotile
