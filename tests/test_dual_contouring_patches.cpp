// Manifold Dual Contouring (DcVertices::Patch): the patch table against Marching Cubes' polygons,
// the face flips that keep two polygons from meeting along two segments, the border rule, and the
// mesh properties the variant exists for, on random volumes, fields and real scans.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <random>
#include <vector>

#include "core/extract/dual_contouring.h"
#include "core/extract/dual_contouring_patches.h"
#include "core/extract/extract.h"
#include "core/extract/marching_cubes.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/mesh/self_intersections.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"

namespace isotile {
namespace {

// Patches without flips or border faces are MC's polygons: the connected components of its
// triangles, every crossed edge in exactly one.
TEST(DcPatches, TheTableIsMarchingCubesPolygons) {
  int multi = 0;
  for (int cs = 0; cs < 256; ++cs) {
    const dc::CellPatches p = dc::cell_patches(cs, 0, 0);
    ASSERT_EQ(p.count, dc::kPatchTable.count[cs]) << "case " << cs;
    EXPECT_EQ(p.patch, dc::kPatchTable.patch[cs]) << "case " << cs;
    std::uint16_t all = 0;
    for (int i = 0; i < p.count; ++i) {
      EXPECT_EQ(p.edges[i], dc::kPatchTable.edges[cs][i]) << "case " << cs;
      EXPECT_EQ(all & p.edges[i], 0) << "case " << cs;
      all |= p.edges[i];
    }
    EXPECT_EQ(all, mc::kCaseTable.edge_mask[cs]) << "case " << cs;
    // Two edges of one MC triangle are in one patch.
    const auto& tri = mc::kCaseTable.triangles[cs];
    for (int t = 0; t < mc::kCaseTable.triangle_count[cs]; ++t)
      for (int v = 1; v < 3; ++v) EXPECT_EQ(p.patch[tri[3 * t]], p.patch[tri[3 * t + v]]);
    multi += p.count > 1;
  }
  // MC separates inside corners on ambiguous faces, so a case and its complement differ there;
  // with every face flipped (outside corners separated) a case has its complement's polygons.
  for (int cs = 0; cs < 256; ++cs)
    EXPECT_EQ(dc::cell_patches(cs, 63, 0).patch, dc::kPatchTable.patch[255 - cs]) << "case " << cs;
  EXPECT_EQ(dc::kPatchTable.count[0], 0);
  EXPECT_GT(multi, 0);
}

// Vertex keys leave room for four patches per cell, whatever faces flip or lie on the border.
TEST(DcPatches, AtMostFourWhateverTheFlipsAndTheBorder) {
  int max = 0, flips_seen = 0;
  for (int cs = 1; cs < 255; ++cs)
    for (unsigned flips = 0; flips < 64; ++flips) {
      if (flips & ~unsigned{dc::kConflictFaces[cs]}) continue;
      flips_seen += flips != 0;
      for (unsigned open = 0; open < 64; ++open) {
        const dc::CellPatches p = dc::cell_patches(cs, flips, open);
        max = std::max(max, p.count);
        ASSERT_LE(p.count, dc::kMaxPatches) << "case " << cs << " flips " << flips;
        // No patch where every crossed edge lies on the border (no quad would use it).
        const bool live = dc::live_edges(cs, open) != 0;
        ASSERT_EQ(p.count >= 1, live) << "case " << cs << " open " << open;
        for (int e = 0; e < 12; ++e)
          EXPECT_EQ(p.patch[e] >= 0, live && ((mc::kCaseTable.edge_mask[cs] >> e) & 1) != 0);
      }
    }
  EXPECT_EQ(max, 4);
  EXPECT_GT(flips_seen, 0);
}

// A flipped face's two segments end up in two patches on each side.
TEST(DcPatches, AFlippedFaceSeparatesItsSegments) {
  int checked = 0;
  for (int cs = 0; cs < 256; ++cs)
    for (int f = 0; f < 6; ++f) {
      if (!((dc::kConflictFaces[cs] >> f) & 1)) continue;
      const dc::CellPatches p = dc::cell_patches(cs, 1u << f, 0);
      EXPECT_EQ(p.count, dc::kPatchTable.count[cs] + 1) << "case " << cs << " face " << f;
      ++checked;
    }
  EXPECT_GT(checked, 0);
}

// Random samples give every configuration, conflicts on faces and at the border included.
Volume noise(const Index3& n, std::uint32_t seed, int levels) {
  Volume v(ScalarType::UInt8, n);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> u(0, levels - 1);
  auto* d = v.data<std::uint8_t>();
  for (std::int64_t i = 0; i < v.sample_count(); ++i) d[i] = static_cast<std::uint8_t>(u(rng));
  return v;
}

// The MC case of cell c, straight from the samples.
int brute_case(const VolumeView& v, double iso, const std::array<std::int64_t, 3>& c) {
  int cs = 0;
  for (int k = 0; k < 8; ++k)
    cs |= (v.value(c[0] + (k & 1), c[1] + ((k >> 1) & 1), c[2] + ((k >> 2) & 1)) >= iso) << k;
  return cs;
}

TEST(DcPatches, RandomVolumesAreManifoldAndWatertight) {
  std::uint64_t cell_nonmanifold = 0, flipped = 0;
  for (int round = 0; round < 24; ++round) {
    const Index3 n{2 + (round * 7) % 31, 2 + (round * 5) % 23, 2 + (round * 3) % 17};
    const Volume v = noise(n, 1000 + round, 2 + round % 3);
    const double iso = 0.5 + round % 2;
    // The repairs counted: every interior face whose two cells both join its segments.
    std::uint64_t want = 0;
    for (std::int64_t z = 0; z + 1 < n[2]; ++z)
      for (std::int64_t y = 0; y + 1 < n[1]; ++y)
        for (std::int64_t x = 0; x + 1 < n[0]; ++x)
          for (int a = 0; a < 3; ++a) {
            std::array<std::int64_t, 3> c{x, y, z}, d = c;
            ++d[a];
            if (d[a] + 1 >= n[a]) continue;
            const int ca = brute_case(v.view(), iso, c), cb = brute_case(v.view(), iso, d);
            want += ((dc::kConflictFaces[ca] >> (2 * a + 1)) & 1) &&
                    ((dc::kConflictFaces[cb] >> (2 * a)) & 1);
          }
    EXPECT_EQ(dual_contouring_patch_repairs(v.view(), iso).flipped_faces, want)
        << "round " << round;
    flipped += want;
    for (DcSolver solver : {DcSolver::MassPoint, DcSolver::Qef}) {
      DualContouringOptions o{.iso = iso, .solver = solver};
      const Mesh m = dual_contouring(v.view(), o);
      const TopologyStats t = mesh_topology(m, volume_border(v.view(), Method::DualContouring));
      EXPECT_EQ(t.nonmanifold_edges, 0u) << "round " << round;
      EXPECT_EQ(t.nonmanifold_vertices, 0u) << "round " << round;
      EXPECT_EQ(t.inconsistently_oriented_edges, 0u) << "round " << round;
      EXPECT_TRUE(t.watertight) << "round " << round << ": " << t.boundary_edges << " boundary, "
                                << t.border_boundary_edges << " on the border";
      // The same faces as the cell variant: one quad per crossed interior edge.
      o.vertices = DcVertices::Cell;
      const Mesh cell = dual_contouring(v.view(), o);
      EXPECT_EQ(m.triangles.size(), cell.triangles.size()) << "round " << round;
      EXPECT_GE(m.positions.size(), cell.positions.size()) << "round " << round;
      cell_nonmanifold += mesh_topology(cell).nonmanifold_edges;
    }
  }
  EXPECT_GT(cell_nonmanifold, 100u);  // what the patches are for
  EXPECT_GT(flipped, 10u);            // the faces the repair is for
}

// Where MC's mesh is closed, so is the dual one, with the same Euler characteristic.
TEST(DcPatches, ClosedWhereMarchingCubesIsWithItsEuler) {
  for (FieldKind kind : {FieldKind::Sphere, FieldKind::Torus, FieldKind::Gyroid, FieldKind::CsgBox,
                         FieldKind::MarschnerLobb}) {
    const Volume v = make_field_volume({kind, 41});
    const VolumeView view = v.view();
    const double iso = field_default_iso(kind);
    const TopologyStats mc = mesh_topology(marching_cubes(view, {.iso = iso}));
    const TopologyStats dc = mesh_topology(dual_contouring(view, {.iso = iso}),
                                           volume_border(view, Method::DualContouring));
    EXPECT_EQ(dc.nonmanifold_edges, 0u);
    EXPECT_EQ(dc.nonmanifold_vertices, 0u);
    EXPECT_EQ(dc.closed, mc.closed) << field_name(kind);
    if (mc.closed) {
      EXPECT_EQ(dc.euler, mc.euler) << field_name(kind);
      EXPECT_EQ(dc.components, mc.components) << field_name(kind);
    }
    EXPECT_TRUE(dc.watertight) << field_name(kind);
  }
}

// The `watertight` rule: an open DC surface ends in the border cells and reads watertight; a hole
// away from the border does not.
TEST(DcPatches, WatertightMeansClosedExceptWhereTheSurfaceLeavesTheVolume) {
  const Volume v = make_field_volume({FieldKind::Gyroid, 24});
  const double iso = field_default_iso(FieldKind::Gyroid);
  const TopologyOptions border = volume_border(v.view(), Method::DualContouring);
  Mesh m = dual_contouring(v.view(), {.iso = iso});
  TopologyStats t = mesh_topology(m, border);
  ASSERT_GT(t.boundary_edges, 100u);
  EXPECT_EQ(t.border_boundary_edges, t.boundary_edges);
  EXPECT_TRUE(t.watertight);
  // With MC's rule (ends on the box face) the same mesh would not read watertight.
  TopologyOptions faces_only = border;
  faces_only.border_inner.reset();
  EXPECT_FALSE(mesh_topology(m, faces_only).watertight);
  // Remove a face in the middle: not watertight.
  std::size_t middle = 0;
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    bool inner = true;
    for (std::uint32_t i : m.triangles[f])
      for (int a = 0; a < 3; ++a) inner = inner && m.positions[i][a] > 3 && m.positions[i][a] < 20;
    if (inner) {
      middle = f;
      break;
    }
  }
  m.triangles.erase(m.triangles.begin() + static_cast<std::ptrdiff_t>(middle));
  t = mesh_topology(m, border);
  EXPECT_FALSE(t.watertight);
  EXPECT_EQ(t.boundary_edges, t.border_boundary_edges + 3);
}

struct RealVolume {
  const char* file;
  double iso;
  bool quality_target;  // mean >= 0.80 and min >= 0.01 (bonsai and engine)
};

// The five volumes of the quality table at their documented isovalues, and the other raw volumes
// of the shared data at the isovalues docs/quality.md gives for them.
TEST(DcPatchesRealData, NoNonManifoldEdgeOrVertexOnTheSharedVolumes) {
  const RealVolume volumes[] = {{"bonsai_256x256x256_uint8.raw.gz", 49.5, true},
                                {"engine_256x256x128_uint8.raw.gz", 49.5, true},
                                {"lobster_301x324x56_uint8.raw.gz", 40.5, false},
                                {"aneurism_256x256x256_uint8.raw.gz", 100.5, false},
                                {"stent_128x128x256_int16.raw.gz", 500.5, false},
                                {"neghip_66x66x66_uint8.raw.gz", 50.5, false},
                                {"bucky_32x32x32_uint8.raw.gz", 100.5, false},
                                {"walnut_128x96x114_uint16.raw.gz", 5000.5, false},
                                {"headsq_quarter_64x64x93_uint16.raw.gz", 1000.5, false},
                                {"hydrogen_orbital_64x64x64_float32.raw.gz", 0.1, false},
                                {"nucleon_41x41x41_uint8.raw.gz", 100.5, false}};
  for (const RealVolume& rv : volumes) {
    const auto path = testing::shared_volume(rv.file);
    ISOTILE_REQUIRE_SHARED(path);
    const Volume vol = read_volume(path.string());
    const Mesh m = dual_contouring(vol.view(), {.iso = rv.iso});
    const TopologyStats t = mesh_topology(m, volume_border(vol.view(), Method::DualContouring));
    EXPECT_EQ(t.nonmanifold_edges, 0u) << rv.file;
    EXPECT_EQ(t.nonmanifold_vertices, 0u) << rv.file;
    EXPECT_EQ(t.inconsistently_oriented_edges, 0u) << rv.file;
    EXPECT_TRUE(t.watertight) << rv.file;
    EXPECT_EQ(self_intersections(m).pairs, 0u) << rv.file;
    if (rv.quality_target) {
      const QualityStats q = triangle_quality(m);
      EXPECT_GE(q.mean, 0.80) << rv.file;
      EXPECT_GE(q.min, 0.01) << rv.file;
    }
  }
}

}  // namespace
}  // namespace isotile
