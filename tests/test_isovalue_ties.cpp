// Samples equal to the isovalue (core/extract/isovalue_ties.h): where Marching Cubes' crossings
// collapse onto such samples, Macet and Dual Contouring give no degenerate triangles, a surface
// through a plane of samples stays on it, and bricks still equal the whole volume.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "core/extract/dual_contouring.h"
#include "core/extract/isovalue_ties.h"
#include "core/extract/macet.h"
#include "core/extract/marching_cubes.h"
#include "core/mesh/mesh_quality.h"
#include "core/volume/volume_io.h"
#include "test_support.h"

namespace isotile {
namespace {

constexpr double kIso = 50;
constexpr std::int64_t kTop = 5;  // the block's top face: the sample plane z = kTop

// uint8 samples at 0 (outside) with shapes made of samples at exactly the isovalue: a speck, a
// rod along x, a one-sample-thin sheet, and a block of 90 whose top layer (z = kTop) is 50, so
// that its top face runs through a plane of samples.
struct TieShapes {
  Index3 dims{26, 22, 20};
  std::vector<std::uint8_t> samples;
  TieShapes() : samples(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]), 0) {
    set(4, 4, 14);                                         // speck
    for (std::int64_t i = 3; i < 12; ++i) set(i, 16, 15);  // rod
    for (std::int64_t i = 14; i < 22; ++i)
      for (std::int64_t j = 12; j < 19; ++j) set(i, j, 14);  // sheet
    for (std::int64_t i = 3; i < 23; ++i)
      for (std::int64_t j = 2; j < 10; ++j)
        for (std::int64_t k = 2; k <= kTop; ++k) set(i, j, k, k == kTop ? 50 : 90);  // block
  }
  void set(std::int64_t i, std::int64_t j, std::int64_t k, std::uint8_t v = 50) {
    samples[static_cast<std::size_t>(i + dims[0] * (j + dims[1] * k))] = v;
  }
  VolumeView view() const { return dense_view(samples.data(), ScalarType::UInt8, dims); }
};

// Vertices above the block's top face, away from its rim: their crossings are all on the face.
template <class F>
void for_top_face_vertices(const Mesh& m, F&& check) {
  int n = 0;
  for (const Vec3f& p : m.positions)
    if (p[0] > 4.5f && p[0] < 20.5f && p[1] > 3.5f && p[1] < 7.5f && p[2] > kTop - 1 &&
        p[2] < kTop + 1) {
      check(p);
      ++n;
    }
  EXPECT_GE(n, 40) << "the block's top face should hold vertices";
}

TEST(IsovalueTies, MarchingCubesCollapsesCrossingsOntoThem) {
  // The premise: with the textbook crossings these shapes give degenerate triangles.
  const TieShapes shapes;
  const QualityStats q = triangle_quality(marching_cubes(shapes.view(), {.iso = kIso}));
  EXPECT_GT(q.degenerate, 20u);
}

TEST(IsovalueTies, MacetGivesNoDegenerateTriangles) {
  const TieShapes shapes;
  for (MacetQuality quality : {MacetQuality::Fast, MacetQuality::Max}) {
    const Mesh m = macet(shapes.view(), {.iso = kIso, .quality = quality});
    const QualityStats q = triangle_quality(m);
    const std::string mode = quality == MacetQuality::Fast ? "fast" : "max";
    EXPECT_EQ(q.degenerate, 0u) << mode;
    EXPECT_GT(q.min, 0.1) << mode;
    for_top_face_vertices(m, [&](const Vec3f& p) {
      EXPECT_NEAR(p[2], static_cast<float>(kTop), 1e-4) << mode << " at " << p[0] << ", " << p[1];
    });
  }
}

// Float32 samples of 0.1 at --iso 0.1: the double 0.1 lies 1.5e-9 below 0.1f, so those samples
// are not equal to it, yet they are its ties in float32 (the float nearest it). Their crossings
// fell within 1.5e-8 edge lengths of them: 466 degenerate triangles of 1,016 (fast), where the
// exact tie 0.10000000149011612 gave none.
std::vector<float> ball_of(float value, const Index3& n) {
  std::vector<float> samples(static_cast<std::size_t>(n[0] * n[1] * n[2]), 0.0f);
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i)
        if ((i - 7.5) * (i - 7.5) + (j - 7.5) * (j - 7.5) + (k - 7.5) * (k - 7.5) < 25)
          samples[static_cast<std::size_t>(i + n[0] * (j + n[1] * k))] = value;
  return samples;
}

TEST(IsovalueTies, MacetTakesFloat32SamplesOfTheNearestFloatAsTies) {
  const Index3 n{16, 16, 16};
  const std::vector<float> samples = ball_of(0.1f, n);
  const VolumeView view = dense_view(samples.data(), ScalarType::Float32, n);
  ASSERT_NE(static_cast<double>(0.1f), 0.1);
  for (MacetQuality quality : {MacetQuality::Fast, MacetQuality::Max}) {
    const std::string mode = quality == MacetQuality::Fast ? "fast" : "max";
    const QualityStats near = triangle_quality(macet(view, {.iso = 0.1, .quality = quality}));
    const QualityStats tie =
        triangle_quality(macet(view, {.iso = static_cast<double>(0.1f), .quality = quality}));
    EXPECT_EQ(near.degenerate, 0u) << mode;
    EXPECT_EQ(tie.degenerate, 0u) << mode;
    EXPECT_NEAR(near.min, tie.min, 1e-3) << mode;
  }
}

// A label map at iso 1: the push or the smoothing moves many ties along the level set (onto
// points where the interpolant is 1 up to rounding, or nearly), and such a tie's crossings would
// all fall on it: Fast gave 3-16 degenerate triangles on 40^3 ones, three vertices on one point.
TEST(IsovalueTies, MacetSpreadsTheCrossingsOfATieMovedAlongTheLevelSet) {
  const Index3 n{24, 24, 24};
  for (unsigned seed = 1; seed <= 6; ++seed) {
    const std::vector<std::uint8_t> samples = testing::random_labels(n, seed);
    const VolumeView view = dense_view(samples.data(), ScalarType::UInt8, n);
    for (MacetQuality quality : {MacetQuality::Fast, MacetQuality::Max}) {
      if (quality == MacetQuality::Max && seed < 5) continue;  // the search is slower
      const Mesh m = macet(view, {.iso = 1, .quality = quality});
      ASSERT_GT(m.triangles.size(), 1000u);
      const std::string mode =
          (quality == MacetQuality::Fast ? "fast, seed " : "max, seed ") + std::to_string(seed);
      EXPECT_EQ(triangle_quality(m).degenerate, 0u) << mode;
      for (const Tri& t : m.triangles)
        ASSERT_TRUE(m.positions[t[0]] != m.positions[t[1]] &&
                    m.positions[t[1]] != m.positions[t[2]] &&
                    m.positions[t[0]] != m.positions[t[2]])
            << mode << ": two corners on one point";
    }
  }
}

TEST(IsovalueTies, DualContouringGivesNoDegenerateTriangles) {
  const TieShapes shapes;
  for (DcSolver solver : {DcSolver::MassPoint, DcSolver::Particle, DcSolver::Qef})
    for (DcHermite hermite : {DcHermite::Central, DcHermite::Eno}) {
      const Mesh m =
          dual_contouring(shapes.view(), {.iso = kIso, .solver = solver, .hermite = hermite});
      const std::string mode = "solver " + std::to_string(static_cast<int>(solver)) + ", hermite " +
                               std::to_string(static_cast<int>(hermite));
      const QualityStats q = triangle_quality(m);
      EXPECT_EQ(q.degenerate, 0u) << mode;
      EXPECT_GT(q.min, 0.1) << mode;
      // Ties that are not pinned keep their crossings: the face is exactly where it was.
      for_top_face_vertices(m, [&](const Vec3f& p) {
        EXPECT_EQ(p[2], static_cast<float>(kTop)) << mode << " at " << p[0] << ", " << p[1];
      });
    }
}

TEST(IsovalueTies, DualContouringSpeckBecomesASmallCube) {
  // The speck's eight cells each have their three crossings kTieOffset from it: their mass points
  // are the corners of a cube of side 2 kTieOffset / 3 around it.
  const TieShapes shapes;
  const Mesh m = dual_contouring(shapes.view(), {.iso = kIso, .keep_quads = true});
  const double h = detail::kTieOffset / 3;
  std::vector<Vec3f> corners;
  for (const Vec3f& p : m.positions) {
    const double d[3] = {p[0] - 4.0, p[1] - 4.0, p[2] - 14.0};
    if (std::abs(d[0]) > 0.5 || std::abs(d[1]) > 0.5 || std::abs(d[2]) > 0.5) continue;
    corners.push_back(p);
    for (double c : d) EXPECT_NEAR(std::abs(c), h, 1e-6);
  }
  ASSERT_EQ(corners.size(), 8u);
  std::sort(corners.begin(), corners.end());
  EXPECT_EQ(std::unique(corners.begin(), corners.end()), corners.end()) << "corners coincide";
}

TEST(IsovalueTies, BricksEqualTheWholeVolume) {
  // Random integers around the isovalue: ties of every kind, pinned or not, at brick borders.
  const Index3 n{21, 18, 16};
  std::vector<std::uint8_t> samples(static_cast<std::size_t>(n[0] * n[1] * n[2]));
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> u(47, 53);
  for (std::uint8_t& s : samples) s = static_cast<std::uint8_t>(u(rng));
  const VolumeView view = dense_view(samples.data(), ScalarType::UInt8, n);
  for (const DualContouringOptions& base :
       {DualContouringOptions{.iso = kIso},
        DualContouringOptions{.iso = kIso, .solver = DcSolver::Qef, .hermite = DcHermite::Eno}}) {
    const testing::KeyedExtract run = [&](const VolumeView& v, const Box3& cells) {
      DualContouringOptions o = base;
      o.cells = cells;
      return testing::KeyedMesh{dual_contouring(v, o), dual_contouring_vertex_keys(v, o)};
    };
    for (const Index3& brick : {Index3{1, 1, 1}, Index3{4, 3, 5}, Index3{9, 7, 8}})
      testing::expect_bricks_equal_whole(view, run, dual_contouring_halo(base), brick);
  }
  const MacetOptions fast{.iso = kIso};
  const testing::KeyedExtract run = [&](const VolumeView& v, const Box3& cells) {
    MacetOptions o = fast;
    o.cells = cells;
    return testing::KeyedMesh{macet(v, o),
                              marching_cubes_vertex_keys(v, {.iso = kIso, .cells = cells})};
  };
  for (const Index3& brick : {Index3{1, 1, 1}, Index3{4, 3, 5}, Index3{9, 7, 8}})
    testing::expect_bricks_equal_whole(view, run, macet_halo(fast), brick);

  // Max's search meets the ties too; a long volume so that brick views end inside it.
  const Index3 m{64, 8, 7};
  std::vector<std::uint8_t> long_samples(static_cast<std::size_t>(m[0] * m[1] * m[2]));
  for (std::uint8_t& s : long_samples) s = static_cast<std::uint8_t>(u(rng));
  const VolumeView long_view = dense_view(long_samples.data(), ScalarType::UInt8, m);
  const MacetOptions max{.iso = kIso, .quality = MacetQuality::Max, .max_sweeps = 1};
  const testing::KeyedExtract run_max = [&](const VolumeView& v, const Box3& cells) {
    MacetOptions o = max;
    o.cells = cells;
    return testing::KeyedMesh{macet(v, o),
                              marching_cubes_vertex_keys(v, {.iso = kIso, .cells = cells})};
  };
  testing::expect_bricks_equal_whole(long_view, run_max, macet_halo(max), Index3{10, 64, 64});
}

TEST(IsovalueTiesRealData, BonsaiAtAnIntegerIsovalueHasNoDegenerateTriangles) {
  // Bonsai at 50 has 10,340 pinned ties; before the offset DC's mass point gave 26,781 degenerate
  // triangles and Macet fast 4,674 (docs/quality.md).
  const auto path = testing::shared_volume("bonsai_256x256x256_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(path);
  const Volume vol = read_volume(path.string());
  const QualityStats dc = triangle_quality(dual_contouring(vol.view(), {.iso = kIso}));
  EXPECT_EQ(dc.degenerate, 0u);
  EXPECT_GE(dc.min, 0.01);
  EXPECT_GE(dc.q01, 0.15);
  const QualityStats fast = triangle_quality(macet(vol.view(), {.iso = kIso}));
  EXPECT_EQ(fast.degenerate, 0u);
  EXPECT_GE(fast.q01, 0.2);
}

}  // namespace
}  // namespace isotile
