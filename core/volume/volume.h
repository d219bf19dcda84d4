// Volumes on uniform grids: a non-owning view (what every algorithm takes) and an owning volume.
//
// Index conventions: sample (i, j, k) of a view lives at data + (i*strides[0] + j*strides[1] +
// k*strides[2]) * scalar_size(type); x varies fastest in a dense volume. A view may be a brick of
// a larger (global) grid: `box` is the part of the global grid it covers, so its local sample
// (0, 0, 0) is global sample box.lo. World position of global sample g is origin + spacing * g,
// for every brick alike, so positions computed from global indices agree bit for bit across
// bricks (the grid frame: what the extractors compute). A volume read from a file that states
// its orientation also carries a WorldFrame: the mesh's positions are mapped into it when they
// are written (core/mesh/mesh_frame.h). All indices are 64-bit.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "core/progress.h"
#include "core/volume/scalar_type.h"

namespace isotile {

using Index3 = std::array<std::int64_t, 3>;
using Vec3d = std::array<double, 3>;
// Row-major 3x3 matrix.
using Mat3 = std::array<double, 9>;
inline constexpr Mat3 kIdentity3{1, 0, 0, 0, 1, 0, 0, 0, 1};

inline double dot(const Vec3d& a, const Vec3d& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
inline Vec3d cross(const Vec3d& a, const Vec3d& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// The rescale slopes and intercepts of a DICOM series whose slices carry their own (each is
// rescaled by its own): their least and greatest.
struct RescaleRange {
  double slope_min = 1, slope_max = 1, intercept_min = 0, intercept_max = 0;
  bool per_slice() const { return slope_min != slope_max || intercept_min != intercept_max; }
};

// Where a grid lies in a file's world space (ITK's convention, LPS for medical images): global
// sample g is at origin + direction * (spacing * g), where column a of `direction` is the unit
// world vector of index axis a. The grid frame (origin + spacing * g) is the special case of the
// identity direction and the same origin.
struct WorldFrame {
  Vec3d origin{0, 0, 0};
  Mat3 direction = kIdentity3;
};

// Half-open box of global sample indices [lo, hi).
struct Box3 {
  Index3 lo{0, 0, 0};
  Index3 hi{0, 0, 0};

  std::int64_t extent(int axis) const { return hi[axis] - lo[axis]; }
  bool empty() const { return extent(0) <= 0 || extent(1) <= 0 || extent(2) <= 0; }
};

struct VolumeView {
  const void* data = nullptr;
  ScalarType type = ScalarType::Float32;
  Index3 dims{0, 0, 0};             // samples along x, y, z
  Index3 strides{0, 0, 0};          // in samples, not bytes
  Vec3d spacing{1, 1, 1};           // world distance between neighbouring samples
  Vec3d origin{0, 0, 0};            // world position of global sample (0, 0, 0)
  Box3 box{};                       // global samples this view covers; box.hi - box.lo == dims
  Index3 global_dims{0, 0, 0};      // dims of the whole volume this view is part of
  std::optional<WorldFrame> world;  // unset: the grid frame is the world

  std::int64_t sample_count() const { return dims[0] * dims[1] * dims[2]; }
  std::int64_t offset(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return i * strides[0] + j * strides[1] + k * strides[2];
  }
  template <class T>
  const T* typed() const {
    return static_cast<const T*>(data);
  }
  // Generic slow accessor (tests, diagnostics); algorithms dispatch on the type once instead.
  double value(std::int64_t i, std::int64_t j, std::int64_t k) const;
};

// A dense view with x fastest, covering the whole global grid.
VolumeView dense_view(const void* data, ScalarType type, Index3 dims, Vec3d spacing = {1, 1, 1},
                      Vec3d origin = {0, 0, 0});

// The part of `view` inside `local` (in the view's own sample indices); clamped to the view.
VolumeView subview(const VolumeView& view, const Box3& local);

// The cells an extractor works on, in the view's own indices. An empty `global_cells` means every
// cell of the view. Otherwise the view must hold those cells and `halo` samples beyond them on
// every side where the volume goes on (InputError if not); the result is clipped to the volume.
Box3 local_cell_box(const VolumeView& view, const Box3& global_cells, int halo);

// An owning dense volume. Samples are left uninitialised on creation (volumes are large and are
// always filled right after).
class Volume {
 public:
  Volume() = default;
  // Throws InputError for zero dims, CapacityError when the byte size overflows.
  Volume(ScalarType type, Index3 dims, Vec3d spacing = {1, 1, 1}, Vec3d origin = {0, 0, 0});

  VolumeView view() const;
  ScalarType type() const { return type_; }
  const Index3& dims() const { return dims_; }
  const Vec3d& spacing() const { return spacing_; }
  const Vec3d& origin() const { return origin_; }
  void set_spacing(const Vec3d& s) { spacing_ = s; }
  void set_origin(const Vec3d& o) { origin_ = o; }
  const std::optional<WorldFrame>& world() const { return world_; }
  void set_world(const std::optional<WorldFrame>& w) { world_ = w; }
  // A DICOM series' UID and description, as read_volume() found them in its headers (what
  // VolumeHeader says); empty for every other input. Front ends name the series by them.
  const std::string& series_uid() const { return series_uid_; }
  const std::string& series_description() const { return series_description_; }
  void set_series(std::string uid, std::string description) {
    series_uid_ = std::move(uid);
    series_description_ = std::move(description);
  }
  std::int64_t sample_count() const { return dims_[0] * dims_[1] * dims_[2]; }
  std::size_t byte_size() const { return bytes_; }
  std::byte* bytes() { return data_.get(); }
  const std::byte* bytes() const { return data_.get(); }
  template <class T>
  T* data() {
    return reinterpret_cast<T*>(data_.get());
  }
  template <class T>
  const T* data() const {
    return reinterpret_cast<const T*>(data_.get());
  }

 private:
  std::unique_ptr<std::byte[]> data_;
  std::size_t bytes_ = 0;
  ScalarType type_ = ScalarType::Float32;
  Index3 dims_{0, 0, 0};
  Vec3d spacing_{1, 1, 1};
  Vec3d origin_{0, 0, 0};
  std::optional<WorldFrame> world_;
  std::string series_uid_, series_description_;
};

// Throws InputError naming `what` unless the grid's geometry makes a mesh: every spacing finite
// and positive (zero flattens the mesh, a negative one turns it inside out), the origin finite,
// and the world frame's origin and direction finite with a direction that is not singular
// (|det| > 1e-6: its columns are unit vectors, so that is far from any real orientation); then
// check_position_range().
void check_grid_geometry(const Index3& dims, const Vec3d& spacing, const Vec3d& origin,
                         const std::optional<WorldFrame>& world, const std::string& what);

// Meshes hold float32 positions (origin + spacing * index in the grid frame, then mapped into the
// world frame when there is one). How finely they resolve a grid: `steps`, the fewest float32
// steps across a cell, where the largest coordinate `at` (of either frame) has steps of `step`
// against the cell's width `cell` (0 where a coordinate passes the largest float32); `largest`:
// the largest coordinate of both frames.
struct PositionResolution {
  double steps = 0, at = 0, step = 0, cell = 0, largest = 0;
};
PositionResolution position_resolution(const Index3& dims, const Vec3d& spacing,
                                       const Vec3d& origin, const std::optional<WorldFrame>& world);

// Throws InputError naming `what` where the grid's positions pass the largest float32 (they
// would be written as inf) or a cell is narrower than a float32 step (its vertices would
// collapse onto each other).
void check_position_range(const Index3& dims, const Vec3d& spacing, const Vec3d& origin,
                          const std::optional<WorldFrame>& world, const std::string& what);

// Fewer float32 steps per cell than this, and the vertices snap to a lattice coarse enough to
// show: nucleon's 9,768 Marching Cubes triangles at 60.5, its grid moved from 0 (1-unit cells):
// at 1e5 and 5e5 (128 and 32 steps) none degenerate and the radius ratios within 0.002 of the
// grid at 0; at 1e6 (16 steps) 8 degenerate; at 5e6 (2 steps, UTM coordinates in metres) 1,143,
// the mean radius ratio 0.59 against 0.66.
inline constexpr double kFewPositionSteps = 32;

// Says to `warn` (core/progress.h), once, where the grid's positions have fewer than
// kFewPositionSteps steps per cell, naming the numbers and the way out; nothing where they have
// enough. `world`: the world frame where the mesh is written in it.
void warn_coarse_positions(const Index3& dims, const Vec3d& spacing, const Vec3d& origin,
                           const std::optional<WorldFrame>& world, const Warn& warn);

// A number as messages show it: 6 significant digits, exponent where needed (0.5, not 0.500000).
// Inline: the ITK reader module, loaded on its own, does not link volume.cpp.
inline std::string short_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

// Number of bytes of dims[0]*dims[1]*dims[2] samples of `type`. Throws InputError when a dim is
// not positive and CapacityError when the product overflows 63 bits.
std::size_t checked_volume_bytes(ScalarType type, const Index3& dims);

}  // namespace isotile
