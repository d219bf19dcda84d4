// Macet on the OpenGL paths (geometry shader, HistoPyramid) against the CPU reference
// (core/extract/macet.h): the same triangles and vertex order, positions bit for bit, for
// fields, a real volume, odd dims, slabs, brick mode, a capture buffer that overflows, relaxation
// and quality Max. Small volumes: llvmpipe runs Macet's double-precision passes on the CPU.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/extract/macet.h"
#include "core/extract/marching_cubes.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "gl_test_support.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "shaders/macet_gl.h"
#include "test_support.h"

namespace isotile {
namespace {

using testing::shared_volume;

using Path = testing::GlPath;

Mesh run(Path p, const VolumeView& v, const gl::MacetGlOptions& o, gl::McStats* stats = nullptr) {
  return p == Path::Gs ? gl::macet_geometry_shader(v, o, stats)
                       : gl::macet_histopyramid(v, o, stats);
}

gl::MacetGlOptions opts(const MacetOptions& m, std::int64_t slab = 0) {
  gl::MacetGlOptions o;
  o.macet = m;
  o.max_brick_cells_z = slab;
  return o;
}

// The CPU's mesh bit for bit (gl_test_support.h).
void expect_same_mesh(const Mesh& gl, const Mesh& cpu, const VolumeView& v,
                      const std::string& what) {
  testing::expect_same_gl_mesh(gl, cpu, v, what);
}

class GlMacet : public ::testing::TestWithParam<Path> {};

// Procedural fields with odd dims, anisotropic spacing and an offset origin.
TEST_P(GlMacet, ProceduralFieldsMatchCpu) {
  REQUIRE_GL();
  for (const char* name : {"field:sphere:17", "field:gyroid:23", "field:torus:19"})
    for (bool normals : {false, true}) {
      const FieldSpec spec = *parse_field_spec(name);
      Volume vol = make_field_volume(spec);
      vol.set_spacing({0.5, 1.0, 2.0});
      vol.set_origin({-3.0, 0.25, 7.0});
      const MacetOptions m{.iso = field_default_iso(spec.kind), .normals = normals};
      const Mesh cpu = macet(vol.view(), m);
      ASSERT_GT(cpu.triangles.size(), 100u);
      expect_same_mesh(run(GetParam(), vol.view(), opts(m)), cpu, vol.view(),
                       std::string(name) + (normals ? " +n" : ""));
    }
}

// Every sample type, many samples exactly at the isovalue: the ties (isovalue_ties.h) and the
// inside test must agree with the CPU; each type is uploaded as stored and widened by the shaders.
TEST_P(GlMacet, IntegerSamplesWithTiesMatchCpu) {
  REQUIRE_GL();
  const Volume field = make_field_volume({FieldKind::Gyroid, 17});
  for (ScalarType t :
       {ScalarType::Int8, ScalarType::UInt8, ScalarType::Int16, ScalarType::UInt16,
        ScalarType::Int32, ScalarType::UInt32, ScalarType::Float32, ScalarType::Float64}) {
    const bool is_unsigned =
        t == ScalarType::UInt8 || t == ScalarType::UInt16 || t == ScalarType::UInt32;
    Volume v(t, field.dims(), field.spacing(), field.origin());
    visit_scalar(t, [&](auto tag) {
      using T = decltype(tag);
      for (std::int64_t i = 0; i < field.sample_count(); ++i)
        v.data<T>()[i] =
            static_cast<T>(std::round(field.data<float>()[i] * 40.0 + (is_unsigned ? 64 : 0)));
    });
    const MacetOptions m{.iso = is_unsigned ? 64.0 : 0.0, .normals = true};
    const Mesh cpu = macet(v.view(), m);
    ASSERT_GT(cpu.triangles.size(), 100u);
    expect_same_mesh(run(GetParam(), v.view(), opts(m)), cpu, v.view(),
                     std::string(scalar_name(t)));
  }
}

// A label map at iso 1: ties moved along the level set get their crossings spread as on the CPU
// (macet_field.h's edge_crossing; the old rule collapses them on this volume, seed 5).
TEST_P(GlMacet, TiesMovedAlongTheLevelSetMatchCpu) {
  REQUIRE_GL();
  const Index3 n{24, 24, 24};
  const std::vector<std::uint8_t> samples = testing::random_labels(n, 5);
  const VolumeView view = dense_view(samples.data(), ScalarType::UInt8, n);
  const MacetOptions m{.iso = 1, .normals = true};
  const Mesh cpu = macet(view, m);
  ASSERT_GT(cpu.triangles.size(), 1000u);
  expect_same_mesh(run(GetParam(), view, opts(m)), cpu, view, "labels");
}

// Float32 samples holding the float nearest the isovalue (0.1f at 0.1) are ties on the device
// too (macet_common.glsl's at_tie, from the float the CPU rounds the isovalue to).
TEST_P(GlMacet, Float32TiesOfTheNearestFloatMatchCpu) {
  REQUIRE_GL();
  const Index3 n{16, 16, 16};
  std::vector<float> samples(static_cast<std::size_t>(n[0] * n[1] * n[2]), 0.0f);
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i)
        if ((i - 7.5) * (i - 7.5) + (j - 7.5) * (j - 7.5) + (k - 7.5) * (k - 7.5) < 25)
          samples[static_cast<std::size_t>(i + n[0] * (j + n[1] * k))] = 0.1f;
  const VolumeView view = dense_view(samples.data(), ScalarType::Float32, n);
  for (MacetQuality quality : {MacetQuality::Fast, MacetQuality::Max}) {
    const MacetOptions m{.iso = 0.1, .normals = true, .quality = quality};
    const Mesh cpu = macet(view, m);
    ASSERT_GT(cpu.triangles.size(), 500u);
    expect_same_mesh(run(GetParam(), view, opts(m)), cpu, view,
                     quality == MacetQuality::Fast ? "0.1f, fast" : "0.1f, max");
  }
}

// Slabs along z (a volume larger than the device's memory): each slab's region holds its cells
// plus macet_halo(), so the mesh is the whole volume's.
TEST_P(GlMacet, SlabsMatchWholeVolume) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Torus, 21});
  const MacetOptions m{.iso = field_default_iso(FieldKind::Torus), .normals = true};
  const Mesh cpu = macet(vol.view(), m);
  for (std::int64_t slab : {1, 6}) {
    gl::McStats stats;
    const Mesh gl = run(GetParam(), vol.view(), opts(m, slab), &stats);
    EXPECT_EQ(stats.bricks, (20 + slab - 1) / slab);
    expect_same_mesh(gl, cpu, vol.view(), "slab " + std::to_string(slab));
  }
}

// Brick mode (the tiler's contract): a box of cells from a view holding it plus macet_halo().
TEST_P(GlMacet, BrickModeMatchesCpu) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 26});
  const VolumeView whole = vol.view();
  const MacetOptions base{.iso = 0.0, .normals = true};
  const int halo = macet_halo(base);
  for (const Box3& cells : {Box3{{0, 0, 0}, {1, 1, 1}}, Box3{{5, 3, 11}, {18, 20, 17}},
                            Box3{{17, 0, 16}, {25, 25, 25}}}) {
    Box3 local;
    for (int a = 0; a < 3; ++a) {
      local.lo[a] = std::max<std::int64_t>(cells.lo[a] - halo, 0);
      local.hi[a] = std::min<std::int64_t>(cells.hi[a] + halo + 1, whole.dims[a]);
    }
    const VolumeView view = subview(whole, local);
    MacetOptions m = base;
    m.cells = cells;
    const Mesh cpu = macet(view, m);
    for (std::int64_t slab : {0, 2})
      expect_same_mesh(run(GetParam(), view, opts(m, slab)), cpu, view, "brick");
  }
}

// A crop of a real CT volume, at a non-integer and an integer isovalue.
TEST_P(GlMacet, RealVolumeCropMatchesCpu) {
  REQUIRE_GL();
  const auto path = shared_volume("neghip_66x66x66_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(path);
  const Volume vol = read_volume(path.string());
  const VolumeView crop = subview(vol.view(), Box3{{10, 12, 9}, {37, 36, 34}});
  for (double iso : {25.5, 100.0}) {
    const MacetOptions m{.iso = iso, .normals = true};
    const Mesh cpu = macet(crop, m);
    ASSERT_GT(cpu.triangles.size(), 500u);
    expect_same_mesh(run(GetParam(), crop, opts(m)), cpu, crop, "neghip " + std::to_string(iso));
  }
}

// Relaxation (the CPU's pre-pass) and quality Max (the CPU's local search between the GL passes).
TEST_P(GlMacet, RelaxAndMaxMatchCpu) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 15});
  const MacetOptions relax{.iso = 0.1, .normals = true, .relax = 0.35};
  const Mesh cpu_relax = macet(vol.view(), relax);
  expect_same_mesh(run(GetParam(), vol.view(), opts(relax, 4)), cpu_relax, vol.view(), "relax");
  const MacetOptions max{.iso = 0.1, .quality = MacetQuality::Max, .max_sweeps = 1};
  const Mesh cpu_max = macet(vol.view(), max);
  ASSERT_FALSE(macet(vol.view(), {.iso = 0.1}).positions == cpu_max.positions);
  expect_same_mesh(run(GetParam(), vol.view(), opts(max, 5)), cpu_max, vol.view(), "max");
}

// Max's halo with the default sweeps is tens of samples, so a slab's planned halo alone can exceed
// the largest binding (llvmpipe: 128 MiB) while the whole volume, whose faces clip the halo, fits:
// it then goes in one slab (an 80^3 volume was refused as "does not fit the GL device's buffers").
TEST_P(GlMacet, MaxWithDefaultSweepsOnAVolumeThatFitsWhole) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::MarschnerLobb, 80});
  const MacetOptions max{.iso = field_default_iso(FieldKind::MarschnerLobb),
                         .quality = MacetQuality::Max};
  ASSERT_GT(macet_halo(max), 40);
  gl::McStats stats;
  expect_same_mesh(run(GetParam(), vol.view(), opts(max), &stats), macet(vol.view(), max),
                   vol.view(), "max, default sweeps");
  EXPECT_EQ(stats.bricks, 1);
}

TEST_P(GlMacet, EmptyAndTinyVolumes) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Sphere, 9});
  EXPECT_TRUE(run(GetParam(), vol.view(), opts({.iso = 1e9})).positions.empty());
  float s[8] = {1, 0, 0, 0, 0, 0, 0, 0};
  const VolumeView tiny = dense_view(s, ScalarType::Float32, {2, 2, 2});
  const Mesh cpu = macet(tiny, {.iso = 0.5});
  ASSERT_EQ(cpu.triangles.size(), 1u);
  expect_same_mesh(run(GetParam(), tiny, opts({.iso = 0.5})), cpu, tiny, "one cell");
  EXPECT_THROW(run(GetParam(), tiny, opts({.iso = 0.5, .relax = 0.5})), InputError);
}

INSTANTIATE_TEST_SUITE_P(Gl, GlMacet, ::testing::Values(Path::Gs, Path::Hp),
                         [](const auto& info) { return info.param == Path::Gs ? "Gs" : "Hp"; });

// A capture buffer far too small: the overflow is detected, the cut cell drawn again.
TEST(GlMacetGeometryShader, CaptureOverflowResumes) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 11});
  const MacetOptions m{.iso = 0.0, .normals = true};
  const Mesh cpu = macet(vol.view(), m);
  for (std::uint64_t bytes : {1u, 3000u}) {
    gl::McStats stats;
    gl::MacetGlOptions o = opts(m, 7);
    o.capture_bytes = bytes;
    const Mesh gl = gl::macet_geometry_shader(vol.view(), o, &stats);
    EXPECT_GT(stats.capture_passes, stats.bricks) << bytes;
    expect_same_mesh(gl, cpu, vol.view(), "overflow " + std::to_string(bytes));
  }
}

// Through extract(): both GL backends run Macet; Auto keeps the CPU on a software rasteriser.
TEST(GlMacetBackends, RegisteredInTheTable) {
  REQUIRE_GL();
  gl::register_gl_backends();
  const Volume vol = make_field_volume({FieldKind::Sphere, 13});
  const Mesh cpu = macet(vol.view(), {.iso = 0.0, .normals = true});
  for (Backend b : {Backend::GeometryShader, Backend::HistoPyramid}) {
    const ExtractOptions o{.method = Method::Macet, .backend = b, .normals = true};
    EXPECT_EQ(resolve_backend(o), b);
    expect_same_mesh(extract(vol.view(), o), cpu, vol.view(), std::string(backend_name(b)));
  }
  const Backend a = resolve_backend({.method = Method::Macet});
  // Never a GL path on a software device; on a GPU whatever the rules say (the CPU everywhere
  // until a GL path is measured faster: kAutoRules).
  if (gl::device().software) {
    EXPECT_EQ(a, Backend::Cpu);
  }
  for (const BackendCaps& c : capabilities())
    if (c.backend != Backend::Cpu) {
      EXPECT_NE(std::find(c.methods.begin(), c.methods.end(), Method::Macet), c.methods.end());
    }
}

}  // namespace
}  // namespace isotile
