// Marching Cubes: exact output on hand-made volumes, properties on procedural fields and real
// volumes, and determinism across thread counts.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <filesystem>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/marching_cubes.h"
#include "core/extract/marching_cubes_tables.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"

namespace isotile {
namespace {

using testing::max_distance;
using testing::shared_volume;

// A triangle rotated so its smallest index comes first; winding is kept.
Tri canonical_rotation(Tri t) {
  while (t[0] > t[1] || t[0] > t[2]) t = {t[1], t[2], t[0]};
  return t;
}

std::array<Vec3f, 2> border_of(const VolumeView& v) {
  std::array<Vec3f, 2> b{};
  for (int a = 0; a < 3; ++a) {
    b[0][a] = static_cast<float>(v.origin[a]);
    b[1][a] = static_cast<float>(v.origin[a] + v.spacing[a] * static_cast<double>(v.dims[a] - 1));
  }
  return b;
}

Mesh mc(const VolumeView& v, double iso, bool normals = false) {
  return marching_cubes(v, {.iso = iso, .normals = normals});
}

TEST(MarchingCubesTables, EveryCaseMatchesItsEdgeMaskAndComplement) {
  for (int c = 0; c < 256; ++c) {
    const auto& t = mc::kCaseTable;
    std::uint16_t used = 0;
    for (int i = 0; i < 3 * t.triangle_count[c]; ++i) {
      ASSERT_GE(t.triangles[c][i], 0);
      used |= 1u << t.triangles[c][i];
    }
    // Every crossed edge carries a vertex and no other edge does.
    EXPECT_EQ(used, t.edge_mask[c]) << "case " << c;
    // Complementary cases cross the same edges.
    EXPECT_EQ(t.edge_mask[c], t.edge_mask[255 - c]);
    // A polygon with n crossings gives n - 2 triangles, so counts are bounded by the edges.
    EXPECT_LE(t.triangle_count[c], std::popcount(t.edge_mask[c]));
  }
  EXPECT_EQ(mc::kCaseTable.triangle_count[0], 0);
  EXPECT_EQ(mc::kCaseTable.triangle_count[255], 0);
}

TEST(MarchingCubes, SingleInsideCornerGivesOneOutwardTriangle) {
  std::vector<float> v(8, 0.0f);
  v[0] = 1.0f;
  const Mesh m = mc(dense_view(v.data(), ScalarType::Float32, {2, 2, 2}), 0.5);
  ASSERT_EQ(m.positions.size(), 3u);
  // Point (0,0,0) owns its x-, y- and z-edge, numbered in that order.
  EXPECT_EQ(m.positions[0], (Vec3f{0.5f, 0, 0}));
  EXPECT_EQ(m.positions[1], (Vec3f{0, 0.5f, 0}));
  EXPECT_EQ(m.positions[2], (Vec3f{0, 0, 0.5f}));
  ASSERT_EQ(m.triangles.size(), 1u);
  // Normal (v1-v0) x (v2-v0) = (+,+,+): away from the inside corner.
  EXPECT_EQ(canonical_rotation(m.triangles[0]), (Tri{0, 1, 2}));
}

TEST(MarchingCubes, SingleOutsideCornerFlipsTheWinding) {
  std::vector<float> v(8, 1.0f);
  v[0] = 0.0f;
  const Mesh m = mc(dense_view(v.data(), ScalarType::Float32, {2, 2, 2}), 0.5);
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(canonical_rotation(m.triangles[0]), (Tri{0, 2, 1}));
}

TEST(MarchingCubes, TwoCellsShareTheirCrossings) {
  // 3x2x2 samples, only (1,0,0) inside: both cells see it, and they share its three edges.
  std::vector<float> v(12, 0.0f);
  v[1] = 1.0f;
  const Mesh m = mc(dense_view(v.data(), ScalarType::Float32, {3, 2, 2}), 0.25);
  ASSERT_EQ(m.positions.size(), 4u);
  // t runs from the lower-index end: (0.25 - v0) / (v1 - v0).
  EXPECT_EQ(m.positions[0], (Vec3f{0.25f, 0, 0}));  // x-edge (0,0,0)-(1,0,0): 0 -> 1, t = 0.25
  EXPECT_EQ(m.positions[1], (Vec3f{1.75f, 0, 0}));  // x-edge (1,0,0)-(2,0,0): 1 -> 0, t = 0.75
  EXPECT_EQ(m.positions[2], (Vec3f{1, 0.75f, 0}));  // y-edge of (1,0,0)
  EXPECT_EQ(m.positions[3], (Vec3f{1, 0, 0.75f}));  // z-edge of (1,0,0)
  ASSERT_EQ(m.triangles.size(), 2u);
  // Cell 0 sees its corner 1 inside: outward means facing -x, i.e. (v0, v3, v2).
  EXPECT_EQ(canonical_rotation(m.triangles[0]), (Tri{0, 3, 2}));
  // Cell 1 sees its corner 0 inside: facing +x, (v1, v2, v3).
  EXPECT_EQ(canonical_rotation(m.triangles[1]), (Tri{1, 2, 3}));
}

// The ambiguous-face rule, pinned by hand-made cells: on a face whose inside corners lie
// diagonally, the segments separate the two inside corners (and so join the two outside ones).
// For every face and both of its diagonals: the two inside corners alone give two triangles,
// each around one corner (its three edge midpoints), in two components; the complement (the two
// outside) gives one hexagon of four triangles. Joining the inside corners instead would give one
// quad in one component, and two separate triangles for the complement.
TEST(MarchingCubes, AmbiguousFacesSeparateTheInsideCorners) {
  using Point = std::array<float, 3>;
  auto corner = [](int c) { return Point{float(c & 1), float((c >> 1) & 1), float((c >> 2) & 1)}; };
  // The midpoints of the three edges at corner c: what a triangle cutting off c must use.
  auto around = [&](int c) {
    std::set<Point> out;
    const Point p = corner(c);
    for (int a = 0; a < 3; ++a) {
      Point q = p;
      q[a] = 0.5f;
      out.insert(q);
    }
    return out;
  };
  int checked = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, w = (axis + 2) % 3;
      // The face's corners (u, w) = (0,0), (1,1) and (1,0), (0,1).
      const int base = side << axis;
      const int diagonals[2][2] = {{base, base | (1 << u) | (1 << w)},
                                   {base | (1 << u), base | (1 << w)}};
      for (const auto& d : diagonals) {
        std::vector<float> v(8, 0.0f);
        v[d[0]] = v[d[1]] = 1.0f;
        const VolumeView view = dense_view(v.data(), ScalarType::Float32, {2, 2, 2});
        const Mesh two = mc(view, 0.5);
        ASSERT_EQ(two.triangles.size(), 2u) << "corners " << d[0] << ", " << d[1];
        std::set<std::set<Point>> got;
        for (const Tri& t : two.triangles) {
          std::set<Point> pts;
          for (std::uint32_t i : t)
            pts.insert({two.positions[i][0], two.positions[i][1], two.positions[i][2]});
          got.insert(pts);
        }
        EXPECT_EQ(got, (std::set<std::set<Point>>{around(d[0]), around(d[1])}))
            << "corners " << d[0] << ", " << d[1];
        EXPECT_EQ(mesh_topology(two).components, 2u);

        for (float& x : v) x = 1.0f - x;
        const Mesh hexagon = mc(view, 0.5);
        EXPECT_EQ(hexagon.triangles.size(), 4u) << "complement of " << d[0] << ", " << d[1];
        EXPECT_EQ(hexagon.positions.size(), 6u);
        EXPECT_EQ(mesh_topology(hexagon).components, 1u);
        ++checked;
      }
    }
  EXPECT_EQ(checked, 12);

  // Across a shared ambiguous face both cells agree (no crack): x = 1 is the face between the
  // cells of a 3 x 2 x 2 volume, with (1,0,0) and (1,1,1) inside.
  std::vector<float> v(12, 0.0f);
  v[1] = v[1 + 3 + 6] = 1.0f;
  const VolumeView view = dense_view(v.data(), ScalarType::Float32, {3, 2, 2});
  const Mesh m = mc(view, 0.5);
  const TopologyStats t = mesh_topology(m, {.border_box = border_of(view)});
  EXPECT_TRUE(t.watertight);
  EXPECT_EQ(t.components, 2u);  // the two corners stay apart across the face too
}

TEST(MarchingCubes, SampleEqualToIsoIsInside) {
  std::vector<float> v(8, 0.0f);
  v[0] = 0.5f;
  const Mesh m = mc(dense_view(v.data(), ScalarType::Float32, {2, 2, 2}), 0.5);
  ASSERT_EQ(m.triangles.size(), 1u);
  for (const Vec3f& p : m.positions) EXPECT_EQ(p, (Vec3f{0, 0, 0}));
}

TEST(MarchingCubes, FlatVolumesAndConstantVolumesGiveEmptyMeshes) {
  std::vector<float> v(4 * 4, 0.0f);
  v[5] = 1.0f;
  EXPECT_TRUE(mc(dense_view(v.data(), ScalarType::Float32, {4, 4, 1}), 0.5).triangles.empty());
  std::vector<float> c(27, 3.0f);
  EXPECT_TRUE(mc(dense_view(c.data(), ScalarType::Float32, {3, 3, 3}), 0.5).positions.empty());
}

// Random volumes exercise every case, ambiguous faces included: the mesh must be crack-free and
// consistently oriented, with boundary edges only on the volume border.
TEST(MarchingCubes, RandomVolumesAreWatertightAndConsistentlyOriented) {
  std::mt19937 rng(12345);
  for (int round = 0; round < 20; ++round) {
    const std::int64_t nx = 3 + round % 7, ny = 2 + round % 5, nz = 70 + round;  // > 64 in z, odd x
    std::vector<std::uint8_t> v(nx * ny * nz);
    std::uniform_int_distribution<int> d(0, 3);
    for (auto& s : v) s = static_cast<std::uint8_t>(d(rng));
    // Transposed so rows longer than one 64-bit word are covered too.
    const VolumeView view = dense_view(v.data(), ScalarType::UInt8, {nz, ny, nx});
    const Mesh m = mc(view, 1.5);
    const TopologyStats t = mesh_topology(m, {.border_box = border_of(view)});
    EXPECT_GT(t.faces, 0u);
    EXPECT_TRUE(t.watertight) << "round " << round << ": " << t.boundary_edges << " boundary, "
                              << t.border_boundary_edges << " on the border";
    EXPECT_EQ(t.nonmanifold_edges, 0u);
    EXPECT_EQ(t.inconsistently_oriented_edges, 0u);
    EXPECT_EQ(t.unreferenced_vertices, 0u);
  }
}

TEST(MarchingCubes, IntegerThresholdAgreesWithFloatingPointComparison) {
  std::mt19937 rng(7);
  std::vector<std::int16_t> s(40 * 33 * 17);
  std::uniform_int_distribution<int> d(-300, 300);
  for (auto& x : s) x = static_cast<std::int16_t>(d(rng));
  std::vector<double> f(s.begin(), s.end());
  for (double iso : {-0.5, 0.0, 17.0, 299.5, -301.0}) {
    const Mesh a = mc(dense_view(s.data(), ScalarType::Int16, {40, 33, 17}), iso);
    const Mesh b = mc(dense_view(f.data(), ScalarType::Float64, {40, 33, 17}), iso);
    EXPECT_EQ(a.positions, b.positions) << "iso " << iso;
    EXPECT_EQ(a.triangles, b.triangles) << "iso " << iso;
  }
}

TEST(MarchingCubes, SubviewGivesGlobalPositions) {
  const Volume vol = make_field_volume({FieldKind::Sphere, 40});
  const VolumeView whole = vol.view();
  const VolumeView part = subview(whole, {{5, 7, 9}, {31, 30, 29}});
  // The same region copied into a dense volume of its own, placed at the same origin offset.
  std::vector<float> copy(26 * 23 * 20);
  for (std::int64_t k = 0; k < 20; ++k)
    for (std::int64_t j = 0; j < 23; ++j)
      for (std::int64_t i = 0; i < 26; ++i)
        copy[(k * 23 + j) * 26 + i] = static_cast<float>(whole.value(i + 5, j + 7, k + 9));
  VolumeView dense = dense_view(copy.data(), ScalarType::Float32, {26, 23, 20});
  dense.box = {{5, 7, 9}, {31, 30, 29}};
  const Mesh a = mc(part, 0.0), b = mc(dense, 0.0);
  ASSERT_GT(a.triangles.size(), 100u);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.triangles, b.triangles);
  for (const Vec3f& p : a.positions)
    for (int c = 0; c < 3; ++c) {
      EXPECT_GE(p[c], part.box.lo[c]);
      EXPECT_LE(p[c], part.box.hi[c] - 1);
    }
}

struct ShapeCase {
  FieldKind kind;
  std::int64_t euler;
};

class ClosedShapes : public ::testing::TestWithParam<ShapeCase> {};

TEST_P(ClosedShapes, AreClosedTwoManifoldsWithTheRightEuler) {
  for (std::int64_t n : {17, 32, 61}) {
    const FieldSpec spec{GetParam().kind, n};
    const Volume vol = make_field_volume(spec);
    const Mesh m = mc(vol.view(), field_default_iso(spec.kind));
    const TopologyStats t = mesh_topology(m);
    EXPECT_TRUE(t.closed) << field_name(spec.kind) << " N=" << n;
    EXPECT_EQ(t.nonmanifold_vertices, 0u);
    EXPECT_EQ(t.inconsistently_oriented_edges, 0u);
    EXPECT_EQ(t.components, 1u);
    EXPECT_EQ(t.euler, GetParam().euler) << field_name(spec.kind) << " N=" << n;
  }
}

INSTANTIATE_TEST_SUITE_P(Fields, ClosedShapes,
                         ::testing::Values(ShapeCase{FieldKind::Sphere, 2},
                                           ShapeCase{FieldKind::CsgBox, 2},
                                           ShapeCase{FieldKind::Torus, 0}),
                         [](const auto& info) {
                           std::string name(field_name(info.param.kind));
                           std::erase(name, '-');
                           return name;
                         });

TEST(MarchingCubes, SmoothSurfacesConvergeAsTheGridRefines) {
  for (FieldKind kind : {FieldKind::Sphere, FieldKind::Torus}) {
    double previous = 1e9;
    for (std::int64_t n : {24, 48, 96}) {
      const FieldSpec spec{kind, n};
      const Volume vol = make_field_volume(spec);
      const double d = max_distance(spec, mc(vol.view(), 0.0));
      // Linear interpolation of a distance field errs by O(h^2 * curvature): in voxel units the
      // error shrinks like 1/N.
      EXPECT_LT(d, 3.0 / static_cast<double>(n)) << field_name(kind) << " N=" << n;
      EXPECT_LT(d, previous) << field_name(kind) << " N=" << n;
      previous = d;
    }
  }
}

TEST(MarchingCubes, NormalsAreUnitAndPointOutOfTheSphere) {
  const FieldSpec spec{FieldKind::Sphere, 48};
  const Volume vol = make_field_volume(spec);
  const Mesh m = mc(vol.view(), 0.0, true);
  ASSERT_EQ(m.normals.size(), m.positions.size());
  const double c = (48 - 1) / 2.0;
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const Vec3f& p = m.positions[i];
    const Vec3f& n = m.normals[i];
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    EXPECT_NEAR(len, 1.0, 1e-5);
    const double r[3] = {p[0] - c, p[1] - c, p[2] - c};
    const double rl = std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    EXPECT_GT((r[0] * n[0] + r[1] * n[1] + r[2] * n[2]) / rl, 0.99);
  }
}

// The normal the extractor documents at the vertex on edge (p, axis) of `v` (global indices): the
// gradient by central differences, one-sided at the volume's border (and at the view's, which a
// view extracted whole without a halo reaches), in world units, interpolated along the edge and
// negated, computed here from the samples without the extractor's code.
Vec3f reference_normal(const VolumeView& v, const Index3& p, int axis, double iso) {
  const auto at = [&](Index3 q) {
    return v.value(q[0] - v.box.lo[0], q[1] - v.box.lo[1], q[2] - v.box.lo[2]);
  };
  const auto gradient = [&](const Index3& q) {
    std::array<double, 3> g{};
    for (int a = 0; a < 3; ++a) {
      Index3 lo = q, hi = q;
      if (q[a] > 0 && q[a] > v.box.lo[a]) --lo[a];
      if (q[a] + 1 < v.global_dims[a] && q[a] + 1 < v.box.lo[a] + v.dims[a]) ++hi[a];
      g[a] = (at(hi) - at(lo)) / (static_cast<double>(hi[a] - lo[a]) * v.spacing[a]);
    }
    return g;
  };
  Index3 p1 = p;
  ++p1[axis];
  const double t = (iso - at(p)) / (at(p1) - at(p));
  const auto g0 = gradient(p), g1 = gradient(p1);
  double n[3], len2 = 0;
  for (int c = 0; c < 3; ++c) {
    n[c] = -(g0[c] + t * (g1[c] - g0[c]));
    len2 += n[c] * n[c];
  }
  const double inv = 1.0 / std::sqrt(len2);
  return {static_cast<float>(n[0] * inv), static_cast<float>(n[1] * inv),
          static_cast<float>(n[2] * inv)};
}

TEST(MarchingCubes, NormalsAreTheSamplesCentralDifferencesAtEveryVertex) {
  // Random samples (every vertex's neighbourhood differs), anisotropic spacing, surface crossing
  // the volume's border; the whole view and a subview of it (a box inside the volume on some
  // sides), at every vertex.
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> d(0, 200);
  const Index3 dims{23, 17, 12};
  std::vector<std::int16_t> data(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]));
  for (auto& s : data) s = static_cast<std::int16_t>(d(rng));
  const VolumeView whole = dense_view(data.data(), ScalarType::Int16, dims, {0.5, 1.0, 2.0});
  const VolumeView part = subview(whole, {{3, 2, 1}, {20, 15, 12}});
  for (const VolumeView& v : {whole, part}) {
    const MarchingCubesOptions o{.iso = 99.5, .normals = true};
    const Mesh m = marching_cubes(v, o);
    const std::vector<std::uint64_t> keys = marching_cubes_vertex_keys(v, o);
    ASSERT_EQ(keys.size(), m.positions.size());
    ASSERT_GT(keys.size(), 1000u);
    for (std::size_t i = 0; i < keys.size(); ++i) {
      const std::uint64_t lin = keys[i] / 3;
      const auto nx = static_cast<std::uint64_t>(v.global_dims[0]),
                 ny = static_cast<std::uint64_t>(v.global_dims[1]);
      const Index3 p{static_cast<std::int64_t>(lin % nx), static_cast<std::int64_t>(lin / nx % ny),
                     static_cast<std::int64_t>(lin / nx / ny)};
      ASSERT_EQ(m.normals[i], reference_normal(v, p, static_cast<int>(keys[i] % 3), o.iso))
          << "vertex " << i;
    }
  }
}

TEST(MarchingCubes, OutputIsIdenticalForAnyThreadCount) {
  const Volume vol = make_field_volume({FieldKind::Gyroid, 150});
  std::vector<Mesh> meshes;
  for (int threads : {1, 2, 8}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    meshes.push_back(mc(vol.view(), 0.0, true));
  }
  ASSERT_GT(meshes[0].triangles.size(), 10000u);
  testing::expect_identical_runs(meshes);
}

TEST(MarchingCubes, VerticesComeInKeyOrderOnTheirEdges) {
  Volume vol = make_field_volume({FieldKind::Gyroid, 37});
  vol.set_spacing({1.0, 0.5, 2.0});
  vol.set_origin({-3.0, 1.0, 0.25});
  const VolumeView v = vol.view();
  const Mesh m = mc(v, 0.1);
  const auto keys = marching_cubes_vertex_keys(v, {.iso = 0.1});
  ASSERT_EQ(keys.size(), m.positions.size());
  ASSERT_GT(keys.size(), 1000u);
  for (std::size_t i = 0; i < keys.size(); ++i) {
    if (i > 0) {
      ASSERT_LT(keys[i - 1], keys[i]);
    }
    const std::uint64_t lin = keys[i] / 3;
    const int axis = static_cast<int>(keys[i] % 3);
    const std::int64_t s[3] = {static_cast<std::int64_t>(lin % 37),
                               static_cast<std::int64_t>(lin / 37 % 37),
                               static_cast<std::int64_t>(lin / (37 * 37))};
    for (int a = 0; a < 3; ++a) {
      const double lo = v.origin[a] + v.spacing[a] * static_cast<double>(s[a]);
      const double hi = a == axis ? lo + v.spacing[a] : lo;
      EXPECT_GE(m.positions[i][a], static_cast<float>(lo)) << "vertex " << i << " axis " << a;
      EXPECT_LE(m.positions[i][a], static_cast<float>(hi)) << "vertex " << i << " axis " << a;
    }
  }
}

// The brick contract the tiler relies on, for brick sizes from one cell to more than the volume.
TEST(MarchingCubes, BricksEqualTheWholeVolume) {
  Volume vol = make_field_volume({FieldKind::Torus, 23});
  vol.set_spacing({0.7, 1.0, 1.3});
  for (bool normals : {false, true}) {
    const MarchingCubesOptions base{.iso = 0.0, .normals = normals};
    const testing::KeyedExtract run = [&](const VolumeView& v, const Box3& cells) {
      MarchingCubesOptions o = base;
      o.cells = cells;
      return testing::KeyedMesh{marching_cubes(v, o), marching_cubes_vertex_keys(v, o)};
    };
    for (const Index3& brick :
         {Index3{1, 1, 1}, Index3{3, 5, 2}, Index3{7, 7, 7}, Index3{22, 4, 9}, Index3{64, 64, 64}})
      testing::expect_bricks_equal_whole(vol.view(), run, marching_cubes_halo(base), brick);
  }
}

TEST(MarchingCubes, BrickModeRejectsAViewWithoutTheHalo) {
  const Volume vol = make_field_volume({FieldKind::Sphere, 16});
  const VolumeView part = subview(vol.view(), {{4, 4, 4}, {10, 10, 10}});
  MarchingCubesOptions o{.iso = 0.0, .normals = true};
  o.cells = {{5, 5, 5}, {8, 8, 8}};  // needs samples 3..10 with normals
  EXPECT_THROW(marching_cubes(part, o), InputError);
  o.normals = false;  // needs samples 4..9
  EXPECT_NO_THROW(marching_cubes(part, o));
}

TEST(MarchingCubesRealData, BonsaiIsWatertightWithThePapersQuality) {
  const auto path = shared_volume("bonsai_256x256x256_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(path);
  const Volume vol = read_volume(path.string());
  const Mesh m = mc(vol.view(), 49.5);
  const TopologyStats t = mesh_topology(m, {.border_box = border_of(vol.view())});
  EXPECT_TRUE(t.watertight) << t.boundary_edges << " boundary edges, " << t.border_boundary_edges
                            << " on the border";
  EXPECT_EQ(t.nonmanifold_edges, 0u);
  EXPECT_EQ(t.inconsistently_oriented_edges, 0u);
  const QualityStats q = triangle_quality(m);
  // The paper's Table I gives 0.688 for MC on its copy of bonsai.
  EXPECT_NEAR(q.mean, 0.688, 0.03);
  // VTK's vtkFlyingEdges3D, the benchmark's peer, gives 669,800 triangles on this volume at 49.5.
  EXPECT_EQ(m.triangles.size(), 669800u);
}

}  // namespace
}  // namespace isotile
