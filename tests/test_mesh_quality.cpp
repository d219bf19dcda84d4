#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "core/errors.h"
#include "core/mesh/mesh_quality.h"

namespace isotile {
namespace {

TEST(RadiusRatio, Equilateral) {
  // Float coordinates cannot make an exactly equilateral triangle; h = sqrt(3)/2 rounded.
  const float h = static_cast<float>(std::sqrt(3.0) / 2);
  EXPECT_NEAR(radius_ratio({0, 0, 0}, {1, 0, 0}, {0.5f, h, 0}), 1.0, 1e-7);
  EXPECT_NEAR(radius_ratio({0, 0, 0}, {0, 2, 0}, {0, 1, 2 * h}), 1.0, 1e-7);
  EXPECT_LE(radius_ratio({0, 0, 0}, {1, 0, 0}, {0.5f, h, 0}), 1.0);
}

TEST(RadiusRatio, RightIsosceles) {
  // Legs a = b = 1, hypotenuse c = sqrt(2):
  //   (b+c-a)(c+a-b)(a+b-c) / (a b c) = sqrt(2) * sqrt(2) * (2 - sqrt(2)) / sqrt(2)
  //                                   = sqrt(2) (2 - sqrt(2)) = 2 (sqrt(2) - 1) = 0.828427...
  const double expected = 2 * (std::sqrt(2.0) - 1);
  EXPECT_NEAR(radius_ratio({0, 0, 0}, {1, 0, 0}, {0, 1, 0}), expected, 1e-15);
  // Scale, translation and orientation do not matter.
  EXPECT_NEAR(radius_ratio({10, 10, 10}, {10, 10, 14}, {10, 14, 10}), expected, 1e-15);
  EXPECT_NEAR(radius_ratio({0, 0, 0}, {0, 1, 0}, {1, 0, 0}), expected, 1e-15);
}

TEST(RadiusRatio, Degenerate) {
  EXPECT_EQ(radius_ratio({0, 0, 0}, {1, 0, 0}, {2, 0, 0}), 0.0);  // collinear
  EXPECT_EQ(radius_ratio({0, 0, 0}, {0, 0, 0}, {1, 1, 0}), 0.0);  // repeated corner
  EXPECT_EQ(radius_ratio({1, 2, 3}, {1, 2, 3}, {1, 2, 3}), 0.0);
  const float nan = std::nanf("");
  EXPECT_EQ(radius_ratio({0, 0, 0}, {1, 0, 0}, {nan, 1, 0}), 0.0);
  const float inf = INFINITY;
  EXPECT_EQ(radius_ratio({0, 0, 0}, {1, 0, 0}, {inf, 1, 0}), 0.0);
}

TEST(RadiusRatio, Sliver) {
  // Isosceles with base 2 and height e: q = 2r/R with r ~ e/2 and R ~ 1/(2e), so q ~ 2e^2;
  // e = 1e-4 gives about 2e-8, which counts as degenerate.
  const double q = radius_ratio({-1, 0, 0}, {1, 0, 0}, {0, 1e-4f, 0});
  EXPECT_GT(q, 1.9e-8);
  EXPECT_LT(q, 2.1e-8);
}

// 1 degenerate, 10 right isosceles and 989 near-equilateral triangles.
Mesh constructed_set() {
  Mesh m;
  const float h = static_cast<float>(std::sqrt(3.0) / 2);
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.5f, h, 0}, {2, 0, 0}};
  m.triangles.push_back({0, 1, 4});
  for (int i = 0; i < 10; ++i) m.triangles.push_back({0, 1, 2});
  for (int i = 0; i < 989; ++i) m.triangles.push_back({0, 1, 3});
  return m;
}

// A face index past the positions (a mesh built by the library's caller) is an InputError, as in
// every other measure; it was read past the positions (a crash).
TEST(TriangleQuality, AnIndexPastThePositionsIsRefused) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 1, 100000000}};
  EXPECT_THROW(triangle_quality(m), InputError);
  m.triangles = {{0, 1, 2}};
  m.quads = {{0, 1, 3, 4}};
  EXPECT_THROW(triangle_quality(m), InputError);
  EXPECT_THROW(split_quad(m.positions, m.quads[0]), InputError);
  m.quads = {{0, 1, 3, 2}};
  EXPECT_EQ(triangle_quality(m).triangles, 3u);
}

TEST(TriangleQuality, ConstructedSet) {
  const Mesh m = constructed_set();
  const double r = radius_ratio({0, 0, 0}, {1, 0, 0}, {0, 1, 0});
  const double e = radius_ratio(m.positions[0], m.positions[1], m.positions[3]);
  const QualityStats s = triangle_quality(m);
  EXPECT_EQ(s.triangles, 1000u);
  EXPECT_EQ(s.degenerate, 1u);
  EXPECT_EQ(s.min, 0.0);
  EXPECT_EQ(s.max, e);
  // Sorted: [0, r x 10, e x 989]. Ranks floor(0.001 * 999) = 0, floor(0.01 * 999) = 9,
  // floor(0.5 * 999) = 499.
  EXPECT_EQ(s.q001, 0.0);
  EXPECT_EQ(s.q01, r);
  EXPECT_EQ(s.median, e);
  EXPECT_NEAR(s.mean, (10 * r + 989 * e) / 1000, 1e-15);
  std::array<std::uint64_t, 20> histogram{};
  histogram[0] = 1;
  histogram[16] = 10;  // 0.828 * 20 = 16.6
  histogram[19] = 989;
  EXPECT_EQ(s.histogram, histogram);
}

TEST(TriangleQuality, QuantileRanks) {
  // Eleven triangles, so n - 1 = 10: q001 and q01 take rank 0 and the median rank 5.
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}};
  for (int i = 1; i <= 11; ++i) {
    // Apex heights 0.05 .. 0.55 give strictly increasing quality.
    m.positions.push_back({0.5f, 0.05f * static_cast<float>(i), 0});
    m.triangles.push_back({0, 1, static_cast<std::uint32_t>(m.positions.size() - 1)});
  }
  std::vector<double> q;
  for (const Tri& t : m.triangles) {
    q.push_back(radius_ratio(m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]));
  }
  ASSERT_TRUE(std::is_sorted(q.begin(), q.end()));
  const QualityStats s = triangle_quality(m);
  EXPECT_EQ(s.q001, q[0]);
  EXPECT_EQ(s.q01, q[0]);
  EXPECT_EQ(s.median, q[5]);
  EXPECT_EQ(s.min, q[0]);
  EXPECT_EQ(s.max, q[10]);
}

TEST(TriangleQuality, QuadTakesBetterDiagonal) {
  Mesh m;
  // Corners 0, 1, 2 are collinear, so diagonal 0-2 would leave a degenerate triangle; diagonal
  // 1-3 gives two right isosceles triangles.
  m.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {1, 1, 0}};
  m.quads = {{0, 1, 2, 3}};
  const double r = 2 * (std::sqrt(2.0) - 1);
  const QualityStats s = triangle_quality(m);
  EXPECT_EQ(s.triangles, 2u);
  EXPECT_EQ(s.degenerate, 0u);
  EXPECT_NEAR(s.min, r, 1e-15);
  EXPECT_NEAR(s.max, r, 1e-15);
  // A unit square: both diagonals give the same two right isosceles triangles.
  Mesh square;
  square.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  square.quads = {{0, 1, 2, 3}};
  const QualityStats sq = triangle_quality(square);
  EXPECT_EQ(sq.triangles, 2u);
  EXPECT_NEAR(sq.mean, r, 1e-15);
}

TEST(TriangleQuality, Empty) {
  const QualityStats s = triangle_quality(Mesh{});
  EXPECT_EQ(s.triangles, 0u);
  EXPECT_EQ(s.mean, 0.0);
  EXPECT_EQ(s.histogram, (std::array<std::uint64_t, 20>{}));
}

TEST(TriangleQuality, HistogramEdges) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  m.triangles = {{0, 1, 2}};
  EXPECT_EQ(triangle_quality(m).histogram[0], 1u);
}

Mesh random_mesh(std::size_t triangles, std::size_t quads) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> u(-1, 1);
  Mesh m;
  for (std::size_t i = 0; i < 3000; ++i) m.positions.push_back({u(rng), u(rng), u(rng)});
  auto v = [&] { return static_cast<std::uint32_t>(rng() % m.positions.size()); };
  for (std::size_t i = 0; i < triangles; ++i) m.triangles.push_back({v(), v(), v()});
  for (std::size_t i = 0; i < quads; ++i) m.quads.push_back({v(), v(), v(), v()});
  return m;
}

// The quantiles are exact where many values share the histogram bin that holds a rank: values
// below 2^-32 (one bin, exact zeros among them), runs of equal values across a rank, and ranks
// that share a bin.
TEST(TriangleQuality, QuantilesExactWithinCrowdedBins) {
  std::mt19937 rng(11);
  for (const std::size_t n : {std::size_t{5001}, std::size_t{20011}}) {
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}};
    std::uniform_real_distribution<float> log_height(-12, -0.1f);
    for (std::size_t i = 0; i < n; ++i) {
      float h = std::pow(10.0f, log_height(rng));
      if (i % 7 == 0) h = 0;                // degenerate: quality exactly 0
      if (i % 5 == 0) h = 1e-9f * (i % 3);  // qualities far below 2^-32
      if (i % 11 == 0) h = 0.5f;            // one value many times over
      if (i > n / 3 && i < n / 3 + 40) h = 0.3f;
      m.positions.push_back({0.5f, h, 0});
      m.triangles.push_back({0, 1, static_cast<std::uint32_t>(m.positions.size() - 1)});
    }
    std::vector<double> q;
    for (const Tri& t : m.triangles) {
      q.push_back(radius_ratio(m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]));
    }
    std::sort(q.begin(), q.end());
    ASSERT_LT(q[(n - 1) / 100], std::ldexp(1.0, -32));  // both low ranks in the lowest bin
    const QualityStats s = triangle_quality(m);
    EXPECT_EQ(s.q001, q[(n - 1) / 1000]);
    EXPECT_EQ(s.q01, q[(n - 1) / 100]);
    EXPECT_EQ(s.median, q[(n - 1) / 2]);
    EXPECT_LT(s.q01, s.median);
  }
}

// Bitwise-equal results whatever the number of threads (many chunks, a quad pair split by a
// chunk border since the triangle count is odd).
TEST(TriangleQuality, DeterministicAcrossThreadCounts) {
  const Mesh m = random_mesh(100001, 30000);
  QualityStats one, many;
  {
    tbb::task_arena arena(1);
    arena.execute([&] { one = triangle_quality(m); });
  }
  many = triangle_quality(m);  // all available threads
  EXPECT_EQ(one.triangles, 160001u);
  EXPECT_EQ(one.mean, many.mean);
  EXPECT_EQ(one.min, many.min);
  EXPECT_EQ(one.max, many.max);
  EXPECT_EQ(one.q001, many.q001);
  EXPECT_EQ(one.q01, many.q01);
  EXPECT_EQ(one.median, many.median);
  EXPECT_EQ(one.degenerate, many.degenerate);
  EXPECT_EQ(one.histogram, many.histogram);

  // Against a plain serial computation.
  std::vector<double> q;
  for (const Tri& t : m.triangles) {
    q.push_back(radius_ratio(m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]));
  }
  for (const Quad& k : m.quads) {
    const auto& p = m.positions;
    const double a0 = radius_ratio(p[k[0]], p[k[1]], p[k[2]]);
    const double a1 = radius_ratio(p[k[0]], p[k[2]], p[k[3]]);
    const double b0 = radius_ratio(p[k[0]], p[k[1]], p[k[3]]);
    const double b1 = radius_ratio(p[k[1]], p[k[2]], p[k[3]]);
    if (std::min(b0, b1) > std::min(a0, a1)) {
      q.push_back(b0);
      q.push_back(b1);
    } else {
      q.push_back(a0);
      q.push_back(a1);
    }
  }
  double sum = 0;
  for (double v : q) sum += v;
  EXPECT_NEAR(one.mean, sum / static_cast<double>(q.size()), 1e-12);
  std::sort(q.begin(), q.end());
  EXPECT_EQ(one.min, q.front());
  EXPECT_EQ(one.max, q.back());
  EXPECT_EQ(one.q001, q[(q.size() - 1) / 1000]);
  EXPECT_EQ(one.q01, q[(q.size() - 1) / 100]);
  EXPECT_EQ(one.median, q[(q.size() - 1) / 2]);
  std::uint64_t total = 0;
  for (auto c : one.histogram) total += c;
  EXPECT_EQ(total, q.size());
  EXPECT_EQ(one.degenerate,
            static_cast<std::uint64_t>(std::lower_bound(q.begin(), q.end(), 1e-6) - q.begin()));
}

}  // namespace
}  // namespace isotile
