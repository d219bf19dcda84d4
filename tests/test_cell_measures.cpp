// The per-vertex cell ranges (scikit-image's `values`), the cell mask and the distance to a
// procedural field's surface: core functions the Python module and the program call. Checked
// against brute force here, so that the sanitizer pass (which cannot load the Python module)
// runs them too.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/cell_mask.h"
#include "core/extract/cell_ranges.h"
#include "core/extract/extract.h"
#include "core/mesh/field_distance.h"
#include "core/volume/finite_range.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume.h"
#include "core/volume/volume_io.h"

namespace isotile {
namespace {

Mesh mc(const VolumeView& view, double iso, Method method = Method::MarchingCubes) {
  ExtractOptions o;
  o.method = method;
  o.backend = Backend::Cpu;
  o.iso = iso;
  return extract(view, o);
}

// The largest range of the cells whose closed box holds p (grid coordinates), every cell tried.
double brute_range(const VolumeView& v, const Vec3f& p) {
  double best = 0;
  for (std::int64_t k = 0; k + 1 < v.dims[2]; ++k)
    for (std::int64_t j = 0; j + 1 < v.dims[1]; ++j)
      for (std::int64_t i = 0; i + 1 < v.dims[0]; ++i) {
        const double g[3] = {(p[0] - v.origin[0]) / v.spacing[0],
                             (p[1] - v.origin[1]) / v.spacing[1],
                             (p[2] - v.origin[2]) / v.spacing[2]};
        const std::int64_t c[3] = {i, j, k};
        bool in = true;
        for (int a = 0; a < 3; ++a) in = in && g[a] >= c[a] - 1e-5 && g[a] <= c[a] + 1 + 1e-5;
        if (!in) continue;
        double lo = INFINITY, hi = -INFINITY;
        for (int n = 0; n < 8; ++n) {
          const double s = v.value(i + (n & 1), j + ((n >> 1) & 1), k + (n >> 2));
          lo = std::min(lo, s);
          hi = std::max(hi, s);
        }
        best = std::max(best, hi - lo);
      }
  return best;
}

TEST(CellRanges, EveryVertexGetsTheLargestRangeOfItsCells) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> sample(0, 99);
  std::vector<std::uint8_t> data(9 * 7 * 6);
  for (auto& s : data) s = static_cast<std::uint8_t>(sample(rng));
  VolumeView view = dense_view(data.data(), ScalarType::UInt8, {9, 7, 6}, {0.5, 1.0, 2.0});
  for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring}) {
    const Mesh mesh = mc(view, 49.5, m);
    ASSERT_GT(mesh.positions.size(), 50u);
    const std::vector<float> values = vertex_cell_ranges(view, mesh);
    ASSERT_EQ(values.size(), mesh.positions.size());
    for (std::size_t v = 0; v < values.size(); ++v)
      EXPECT_EQ(values[v], static_cast<float>(brute_range(view, mesh.positions[v])))
          << "method " << method_name(m) << " vertex " << v;
  }
}

TEST(CellRanges, StridedViewsAndThinVolumesAgreeWithDenseOnes) {
  // A strided view (every other sample along y of a larger array) against its dense copy.
  const Volume big = make_field_volume({FieldKind::Torus, 24});
  VolumeView strided = big.view();
  strided.dims[1] = 12;
  strided.strides[1] *= 2;
  strided.box.hi = strided.dims;
  strided.global_dims = strided.dims;
  std::vector<float> dense(static_cast<std::size_t>(strided.sample_count()));
  for (std::int64_t k = 0; k < strided.dims[2]; ++k)
    for (std::int64_t j = 0; j < strided.dims[1]; ++j)
      for (std::int64_t i = 0; i < strided.dims[0]; ++i)
        dense[(k * strided.dims[1] + j) * strided.dims[0] + i] =
            static_cast<float>(strided.value(i, j, k));
  const VolumeView dense_v = dense_view(dense.data(), ScalarType::Float32, strided.dims);
  const Mesh a = mc(strided, 0.0), b = mc(dense_v, 0.0);
  ASSERT_EQ(a.positions, b.positions);
  EXPECT_EQ(vertex_cell_ranges(strided, a), vertex_cell_ranges(dense_v, b));
  // Two samples thin along z: one layer of cells.
  std::vector<float> thin = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17};
  const VolumeView t = dense_view(thin.data(), ScalarType::Float32, {3, 3, 2});
  const Mesh m = mc(t, 8.5);
  ASSERT_FALSE(m.positions.empty());
  const std::vector<float> values = vertex_cell_ranges(t, m);
  for (std::size_t v = 0; v < values.size(); ++v)
    EXPECT_EQ(values[v], static_cast<float>(brute_range(t, m.positions[v])));
}

// Whether p (grid frame of v) lies between 1e-6 and 2e-4 voxels from a grid plane.
bool near_a_plane(const VolumeView& v, const Vec3f& p) {
  for (int a = 0; a < 3; ++a) {
    const double g = (p[a] - v.origin[a]) / v.spacing[a];
    const double d = std::abs(g - std::round(g));
    if (d > 1e-6 && d < 2e-4) return true;
  }
  return false;
}

// vertex_cell_ranges() run in an arena of `threads` threads.
std::vector<float> ranges_at(int threads, const VolumeView& view, const Mesh& mesh) {
  tbb::task_arena arena(threads);
  return arena.execute([&] { return vertex_cell_ranges(view, mesh); });
}

TEST(CellRanges, SameValuesAtAnyThreadCountForEveryMethodAndType) {
  // Vertices on edges, at grid points (an integer level on integer samples) and inside cells.
  const Volume field = make_field_volume({FieldKind::Gyroid, 48});
  std::vector<std::int16_t> shorts(static_cast<std::size_t>(field.view().sample_count()));
  for (std::size_t s = 0; s < shorts.size(); ++s)
    shorts[s] = static_cast<std::int16_t>(std::lround(field.view().typed<float>()[s] * 100));
  const VolumeView views[] = {
      field.view(), dense_view(shorts.data(), ScalarType::Int16, field.view().dims, {1, 2, 0.5})};
  for (const VolumeView& view : views)
    for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring})
      for (double iso : {0.0, 0.25, 30.0}) {
        if (view.type == ScalarType::Float32 && iso > 1) continue;
        const Mesh mesh = mc(view, iso, m);
        ASSERT_GT(mesh.positions.size(), 10000u);  // several tasks of 4096
        const std::vector<float> one = ranges_at(1, view, mesh);
        EXPECT_EQ(ranges_at(2, view, mesh), one) << method_name(m) << " iso " << iso;
        // Against every cell tried, for a sample of the vertices; not those whose distance to a
        // grid plane lies between brute_range's tolerance and the library's (1e-5 and 1e-4
        // voxels), where the two may count different cells.
        for (std::size_t v = 0; v < one.size(); v += 97)
          if (!near_a_plane(view, mesh.positions[v])) {
            EXPECT_EQ(one[v], static_cast<float>(brute_range(view, mesh.positions[v])))
                << method_name(m) << " iso " << iso << " vertex " << v;
          }
      }
}

// finite_value_range() in an arena of `threads` threads.
std::pair<double, double> finite_range_at(int threads, const VolumeView& view) {
  tbb::task_arena arena(threads);
  return arena.execute([&] { return finite_value_range(view, "volume"); });
}

// The bounds by a plain loop over every sample of `v` (finite samples).
template <class T>
std::pair<double, double> brute_range(const VolumeView& v) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::int64_t k = 0; k < v.dims[2]; ++k)
    for (std::int64_t j = 0; j < v.dims[1]; ++j)
      for (std::int64_t i = 0; i < v.dims[0]; ++i) {
        const double s = static_cast<double>(v.typed<T>()[v.offset(i, j, k)]);
        lo = std::min(lo, s);
        hi = std::max(hi, s);
      }
  return {lo, hi};
}

template <class T>
void expect_fused_range_matches(const std::vector<T>& samples, Index3 dims) {
  const ScalarType type = scalar_type_of<T>();
  const VolumeView dense = dense_view(samples.data(), type, dims);
  // The same samples read every other x (a strided row) and a sub-box of them.
  VolumeView strided = dense;
  strided.dims[0] = (dims[0] + 1) / 2;
  strided.strides[0] = 2;
  strided.box.hi = strided.global_dims = strided.dims;
  VolumeView inner = dense;
  inner.data = samples.data() + dense.offset(1, 1, 1);
  inner.dims = {dims[0] - 2, dims[1] - 2, dims[2] - 1};
  inner.box.hi = inner.global_dims = inner.dims;
  for (const VolumeView& v : {dense, strided, inner}) {
    check_finite(v, "volume");  // these are finite
    const auto want = brute_range<T>(v);
    EXPECT_EQ(finite_range_at(1, v), want) << scalar_name(type);
    EXPECT_EQ(finite_range_at(2, v), want) << scalar_name(type);
    EXPECT_EQ(value_range(v), want) << scalar_name(type);
  }
}

// `n` samples drawn uniformly from [lo, hi).
template <class T>
std::vector<T> random_samples(std::mt19937& rng, std::size_t n, double lo, double hi) {
  std::uniform_real_distribution<double> d(lo, hi);
  std::vector<T> v(n);
  for (auto& s : v) s = static_cast<T>(d(rng));
  return v;
}

TEST(FiniteValueRange, BothRangesEqualAPlainLoopForEveryTypeAndLayout) {
  std::mt19937 rng(11);
  // Rows of 67 samples: whole SIMD lanes and a tail; the extremes placed at a tail, a lane and
  // the first sample of some row.
  const Index3 dims{67, 9, 8};
  const auto n = static_cast<std::size_t>(dims[0] * dims[1] * dims[2]);
  auto u8 = random_samples<std::uint8_t>(rng, n, 10, 200);
  u8[66] = 3;
  u8[67 * 9 * 3 + 17] = 250;
  expect_fused_range_matches(u8, dims);
  auto i8 = random_samples<std::int8_t>(rng, n, -100, 100);
  i8[n - 1] = -128;
  expect_fused_range_matches(i8, dims);
  expect_fused_range_matches(random_samples<std::uint16_t>(rng, n, 100, 60000), dims);
  expect_fused_range_matches(random_samples<std::int16_t>(rng, n, -30000, 30000), dims);
  expect_fused_range_matches(random_samples<std::uint32_t>(rng, n, 0, 4e9), dims);
  expect_fused_range_matches(random_samples<std::int32_t>(rng, n, -2e9, 2e9), dims);
  auto f32 = random_samples<float>(rng, n, -1, 1);
  f32[67 * 2] = -7.5f;
  f32[67 * 5 + 64] = 9.25f;
  expect_fused_range_matches(f32, dims);
  // Float64 samples past kLargestFloat64Sample (1e100) are refused.
  expect_fused_range_matches(random_samples<double>(rng, n, -1e100, 1e100), dims);
  // -0.0 and +0.0 both as the minimum: a +0.0 bound whatever the split of the rows.
  std::vector<float> zeros(n, 1.0f);
  for (std::size_t s = 0; s < n; s += 3) zeros[s] = (s / 3) % 2 ? -0.0f : 0.0f;
  for (int threads : {1, 2}) {
    const auto r = finite_range_at(threads, dense_view(zeros.data(), ScalarType::Float32, dims));
    EXPECT_EQ(r.first, 0.0);
    EXPECT_FALSE(std::signbit(r.first)) << threads << " threads";
  }
  // Empty views give (0, 0), as value_range says.
  const VolumeView empty = dense_view(f32.data(), ScalarType::Float32, {0, 3, 3});
  EXPECT_EQ(finite_value_range(empty, "volume"), std::make_pair(0.0, 0.0));
}

// The message check_finite() gives for `v`.
std::string check_finite_message(const VolumeView& v) {
  try {
    check_finite(v, "volume");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(FiniteValueRange, RejectsNanAndInfAsCheckFiniteDoes) {
  const Index3 dims{67, 5, 4};
  const auto n = static_cast<std::size_t>(dims[0] * dims[1] * dims[2]);
  for (const double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity()})
    // In a lane, in a row's tail, and the very first sample (where the lanes start).
    for (const std::size_t at :
         {std::size_t{67 * 3 + 10}, std::size_t{67 * 7 + 66}, std::size_t{0}}) {
      std::vector<float> f(n, 1.0f);
      std::vector<double> d(n, 1.0);
      f[at] = static_cast<float>(bad);
      d[at] = bad;
      for (const VolumeView& v : {dense_view(f.data(), ScalarType::Float32, dims),
                                  dense_view(d.data(), ScalarType::Float64, dims)}) {
        const std::string want = check_finite_message(v);
        ASSERT_FALSE(want.empty());
        for (int threads : {1, 2}) {
          try {
            finite_range_at(threads, v);
            ADD_FAILURE() << "no error for " << bad << " at " << at;
          } catch (const InputError& e) {
            EXPECT_EQ(std::string(e.what()), want);
          }
        }
      }
    }
}

std::set<std::array<float, 9>> triangle_set(const Mesh& m, const std::vector<Tri>& tris) {
  std::set<std::array<float, 9>> out;
  for (const Tri& t : tris) {
    std::array<Vec3f, 3> p = {m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]};
    std::sort(p.begin(), p.end());
    out.insert({p[0][0], p[0][1], p[0][2], p[1][0], p[1][1], p[1][2], p[2][0], p[2][1], p[2][2]});
  }
  return out;
}

TEST(CellMask, KeepsTheFacesOfCellsWhoseCornersAreAllSet) {
  const Volume vol = make_field_volume({FieldKind::Sphere, 20});
  const VolumeView view = vol.view();
  const Mesh full = mc(view, 0.0);
  std::vector<std::uint8_t> all(static_cast<std::size_t>(view.sample_count()), 1);
  const VolumeView all_v = dense_view(all.data(), ScalarType::UInt8, view.dims);
  const Mesh same = keep_masked_cells(full, view, all_v);
  EXPECT_EQ(same.positions, full.positions);
  EXPECT_EQ(same.triangles, full.triangles);

  // Samples with x <= 9 set: cells with x in 0..8 are inside.
  std::vector<std::uint8_t> half(all.size(), 0);
  for (std::size_t s = 0; s < half.size(); ++s) half[s] = s % 20 <= 9;
  const Mesh kept =
      keep_masked_cells(full, view, dense_view(half.data(), ScalarType::UInt8, view.dims));
  std::vector<Tri> want;
  for (const Tri& t : full.triangles) {
    const float cx =
        (full.positions[t[0]][0] + full.positions[t[1]][0] + full.positions[t[2]][0]) / 3;
    if (std::floor(cx) <= 8) want.push_back(t);
  }
  ASSERT_FALSE(want.empty());
  ASSERT_LT(want.size(), full.triangles.size());
  EXPECT_EQ(triangle_set(kept, kept.triangles), triangle_set(full, want));
  // Every kept vertex is used, in the original order.
  std::vector<bool> used(kept.positions.size());
  for (const Tri& t : kept.triangles)
    for (auto v : t) used[v] = true;
  EXPECT_TRUE(std::all_of(used.begin(), used.end(), [](bool u) { return u; }));

  EXPECT_THROW(keep_masked_cells(full, view, view), InputError);  // float32, not a mask
  const VolumeView wrong = dense_view(all.data(), ScalarType::UInt8, {20, 20, 19});
  EXPECT_THROW(keep_masked_cells(full, view, wrong), InputError);
}

TEST(FieldDistance, MeanAndMaxOfTheVertexDistances) {
  const FieldSpec spec{FieldKind::Sphere, 32};
  const Volume vol = make_field_volume(spec);
  const Mesh mesh = mc(vol.view(), 0.0);
  ASSERT_GT(mesh.positions.size(), 1000u);
  double sum = 0, max = 0;
  for (const Vec3f& p : mesh.positions) {
    const double d = distance_voxels(spec, {p[0], p[1], p[2]});
    sum += d;
    max = std::max(max, d);
  }
  const FieldDistance d = field_distance(spec, mesh, {0, 0, 0}, {1, 1, 1});
  EXPECT_NEAR(d.mean, sum / static_cast<double>(mesh.positions.size()), 1e-12);
  EXPECT_EQ(d.max, max);
  EXPECT_GT(d.max, 0.0);
  EXPECT_LT(d.max, 0.1);
  // A scaled and shifted frame gives the same voxel distances.
  Mesh moved = mesh;
  for (Vec3f& p : moved.positions)
    for (int a = 0; a < 3; ++a) p[a] = static_cast<float>(p[a] * 2.0 + 1.0);
  EXPECT_NEAR(field_distance(spec, moved, {1, 1, 1}, {2, 2, 2}).mean, d.mean, 1e-6);
  EXPECT_EQ(field_distance(spec, Mesh{}, {0, 0, 0}, {1, 1, 1}).max, 0.0);
}

}  // namespace
}  // namespace isotile
