#include "core/mesh/self_intersections.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstdint>
#include <limits>

#include "core/errors.h"
#include "core/extract/dual_contouring.h"
#include "core/extract/marching_cubes.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"

namespace isotile {
namespace {

// A mesh from loose triangles (three fresh vertices each) or from shared vertices.
Mesh soup(const std::vector<std::array<Vec3f, 3>>& tris) {
  Mesh m;
  for (const auto& t : tris) {
    const auto base = static_cast<std::uint32_t>(m.positions.size());
    for (const Vec3f& p : t) m.positions.push_back(p);
    m.triangles.push_back({base, base + 1, base + 2});
  }
  return m;
}

std::uint64_t count(const Mesh& m) {
  return self_intersections(m).pairs;
}

TEST(SelfIntersections, CrossingTrianglesIntersect) {
  // A horizontal triangle pierced by a vertical one.
  EXPECT_EQ(
      count(soup({{{{0, 0, 0}, {4, 0, 0}, {0, 4, 0}}}, {{{1, 1, -1}, {1, 1, 1}, {2, 0.5f, 0}}}})),
      1u);
}

TEST(SelfIntersections, SeparatedTrianglesDoNot) {
  EXPECT_EQ(count(soup({{{{0, 0, 0}, {4, 0, 0}, {0, 4, 0}}},
                        {{{1, 1, 0.01f}, {1, 1, 1}, {2, 0.5f, 0.5f}}}})),
            0u);
  // Parallel, one above the other, boxes overlapping in x and y.
  EXPECT_EQ(count(soup({{{{0, 0, 0}, {4, 0, 0}, {0, 4, 0}}}, {{{0, 0, 1}, {4, 0, 1}, {0, 4, 1}}}})),
            0u);
}

TEST(SelfIntersections, TouchingWithoutSharingCounts) {
  // A vertex of the second lies inside the first: a contact, not a shared vertex.
  EXPECT_EQ(count(soup({{{{0, 0, 0}, {4, 0, 0}, {0, 4, 0}}}, {{{1, 1, 0}, {1, 1, 1}, {2, 1, 1}}}})),
            1u);
  // Coplanar overlap.
  EXPECT_EQ(count(soup({{{{0, 0, 0}, {4, 0, 0}, {0, 4, 0}}}, {{{1, 1, 0}, {5, 1, 0}, {1, 5, 0}}}})),
            1u);
}

TEST(SelfIntersections, SharedEdgeOnlyWhenFolded) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {0.5f, 0.2f, 0}, {0.3f, 0.3f, 1}};
  m.triangles = {{0, 1, 2}, {2, 1, 3}};  // flat, opposite sides of the edge: adjacent
  EXPECT_EQ(count(m), 0u);
  m.triangles = {{0, 1, 2}, {1, 0, 5}};  // bent: meet along the edge only
  EXPECT_EQ(count(m), 0u);
  m.triangles = {{0, 1, 2}, {1, 0, 4}};  // coplanar, both on one side: folded onto each other
  EXPECT_EQ(count(m), 1u);
  m.triangles = {{0, 1, 2}, {2, 1, 0}};  // the same triangle twice
  EXPECT_EQ(count(m), 1u);
}

TEST(SelfIntersections, SharedVertex) {
  Mesh m;
  // Vertex 0 shared. 1, 2 span a triangle in z = 0; the others are placed per case.
  m.positions = {{0, 0, 0},     {2, 0, 0},        {0, 2, 0},       {-1, 0.5f, -1},
                 {-1, 0.5f, 1}, {0.5f, 0.5f, -1}, {0.5f, 0.5f, 1}, {-2, 0, 0},
                 {0, -2, 0},    {1, 1, 0},        {2, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 3, 4}};  // a fan neighbour on the far side: only the vertex
  EXPECT_EQ(count(m), 0u);
  m.triangles = {{0, 1, 2}, {0, 5, 6}};  // its opposite edge pierces the first triangle
  EXPECT_EQ(count(m), 1u);
  m.triangles = {{0, 1, 2}, {0, 7, 8}};  // coplanar, opposite wedges
  EXPECT_EQ(count(m), 0u);
  m.triangles = {{0, 1, 2}, {0, 9, 10}};  // coplanar, overlapping wedges
  EXPECT_EQ(count(m), 1u);
  m.triangles = {{0, 1, 2}, {0, 9, 6}};  // its edge 0-9 runs inside the first triangle
  EXPECT_EQ(count(m), 1u);
}

TEST(SelfIntersections, VerticesAreIdentifiedByPosition) {
  // Two flat neighbours with duplicated (unwelded) shared vertices are still adjacent.
  EXPECT_EQ(count(soup({{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}}, {{{0, 1, 0}, {1, 0, 0}, {1, 1, 0}}}})),
            0u);
  const SelfIntersections r = self_intersections(
      soup({{{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}}, {{{0, 0, 0}, {1, 1, 0}, {1, 1, 0}}}}));
  EXPECT_EQ(r.pairs, 0u);
  EXPECT_EQ(r.skipped, 2u);  // collinear, and two equal corners
}

TEST(SelfIntersections, QuadsCountAsTwoTriangles) {
  Mesh m;
  m.positions = {{0, 0, 0},  {2, 0, 0}, {2, 2, 0},      {0, 2, 0},
                 {1, 1, -1}, {1, 1, 1}, {1.5f, 0.2f, 0}};
  m.quads = {{0, 1, 2, 3}};
  EXPECT_EQ(count(m), 0u);
  m.triangles = {{4, 5, 6}};  // crosses the quad's diagonal and enters its triangle (0, 1, 2)
  const SelfIntersections r = self_intersections(m, {.max_pairs = 10});
  ASSERT_GE(r.pairs, 1u);
  EXPECT_EQ(r.examples.front(), (std::array<std::uint64_t, 2>{0, 1}));
}

TEST(SelfIntersections, BadIndexThrows) {
  Mesh m;
  m.positions = {{0, 0, 0}};
  m.triangles = {{0, 0, 1}};
  EXPECT_THROW(self_intersections(m), InputError);
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, std::numeric_limits<float>::quiet_NaN(), 0}};
  m.triangles = {{0, 1, 2}};
  EXPECT_THROW(self_intersections(m), InputError);
}

Mesh mc_field(FieldKind kind, std::int64_t n) {
  const Volume v = make_field_volume({kind, n});
  return marching_cubes(v.view(), {.iso = field_default_iso(kind)});
}

// Appends a copy of `m` moved by `shift`.
Mesh with_shifted_copy(const Mesh& m, const Vec3f& shift) {
  Mesh out = m;
  const auto base = static_cast<std::uint32_t>(m.positions.size());
  for (Vec3f p : m.positions) {
    for (int a = 0; a < 3; ++a) p[a] += shift[a];
    out.positions.push_back(p);
  }
  for (Tri t : m.triangles) out.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  return out;
}

TEST(SelfIntersections, ClosedSurfacesHaveNone) {
  for (FieldKind kind : {FieldKind::Sphere, FieldKind::Torus, FieldKind::Gyroid}) {
    const Mesh m = mc_field(kind, 48);
    ASSERT_GT(m.triangles.size(), 1000u);
    EXPECT_EQ(count(m), 0u) << field_name(kind);
  }
  const Volume v = make_field_volume({FieldKind::Sphere, 40});
  const Mesh dc = dual_contouring(v.view(), {});
  EXPECT_EQ(count(dc), 0u);
}

// Brute force over all pairs with the same narrow phase checks the grid broad phase.
TEST(SelfIntersections, GridFindsEveryPairBruteForceFinds) {
  const Mesh m = with_shifted_copy(mc_field(FieldKind::Sphere, 14), {0.37f, 0.21f, 0.13f});
  std::vector<std::array<std::uint64_t, 2>> want;
  const auto& p = m.positions;
  // Welded ids: here every position is distinct within a copy and the shift makes copies differ.
  for (std::size_t i = 0; i < m.triangles.size(); ++i)
    for (std::size_t j = i + 1; j < m.triangles.size(); ++j) {
      const Tri &a = m.triangles[i], &b = m.triangles[j];
      if (triangles_intersect({p[a[0]], p[a[1]], p[a[2]]}, a, {p[b[0]], p[b[1]], p[b[2]]}, b))
        want.push_back({i, j});
    }
  ASSERT_GT(want.size(), 50u);
  const SelfIntersections r = self_intersections(m, {.max_pairs = want.size() + 1});
  EXPECT_EQ(r.pairs, want.size());
  EXPECT_EQ(r.examples, want);
  // The original half alone is clean: every pair found involves both copies.
  const std::size_t half = m.triangles.size() / 2;
  for (const auto& e : r.examples) EXPECT_TRUE(e[0] < half && e[1] >= half);
}

TEST(SelfIntersections, ShiftedCopyHasManyAndCountIsThreadIndependent) {
  const Mesh m = with_shifted_copy(mc_field(FieldKind::Torus, 64), {0.3f, 0.45f, 0.2f});
  std::uint64_t one = 0;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = count(m);
  }
  // The copies cross along closed curves several hundred voxels long in all.
  EXPECT_GT(one, 500u);
  EXPECT_EQ(count(m), one);
}

// On the paper's volumes DC's default (each vertex the mean of its cell's crossings) has measured
// no self-intersections, while the QEF, which moves vertices toward corners and lines of its
// planes, has some (docs/quality.md). A regression guard, with the contrast that shows the check
// can see them.
TEST(SelfIntersectionsRealData, DcMassPointHasNoneWhereTheQefHasSome) {
  const auto path = testing::shared_volume("engine_256x256x128_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(path);
  const Volume vol = read_volume(path.string());
  const Mesh mass = dual_contouring(vol.view(), {.iso = 49.5});
  const Mesh qef = dual_contouring(vol.view(), {.iso = 49.5, .solver = DcSolver::Qef});
  ASSERT_GT(mass.triangles.size(), 500000u);
  EXPECT_EQ(count(mass), 0u);
  EXPECT_GT(count(qef), 0u);
}

}  // namespace
}  // namespace isotile
