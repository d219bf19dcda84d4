// Dual Contouring on the OpenGL backends (HistoPyramid, geometry shader) against the CPU
// reference (core/extract/dual_contouring.h): the same vertices in key order, the same faces in
// the same order, positions and normals bit for bit, for every vertex variant, solver and Hermite
// choice, whole-volume, in slabs, in brick mode, with a capture buffer that overflows. Small
// volumes: llvmpipe runs the shaders on the CPU.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/dual_contouring.h"
#include "core/extract/extract.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "gl_test_support.h"
#include "shaders/dc_gl.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "test_support.h"

namespace isotile {
namespace {

using testing::shared_volume;

using Path = testing::GlPath;

Mesh run(Path p, const VolumeView& v, const gl::DcGlOptions& o, gl::McStats* stats = nullptr) {
  return p == Path::Gs ? gl::dc_geometry_shader(v, o, stats) : gl::dc_histopyramid(v, o, stats);
}

gl::DcGlOptions gl_options(const DualContouringOptions& dc, std::int64_t slab = 0) {
  gl::DcGlOptions o;
  o.dc = dc;
  o.max_brick_cells_z = slab;
  return o;
}

std::string describe(const DualContouringOptions& o) {
  std::string s = o.vertices == DcVertices::Patch ? "patch" : "cell";
  s += o.solver == DcSolver::MassPoint  ? " mass"
       : o.solver == DcSolver::Particle ? " particle"
                                        : " qef";
  s += o.hermite == DcHermite::Central ? " central" : " eno";
  if (o.keep_quads) s += " quads";
  if (o.normals) s += " normals";
  return s;
}

// The CPU's mesh bit for bit (gl_test_support.h).
void expect_same_mesh(const Mesh& gl, const Mesh& cpu, const VolumeView& v,
                      const std::string& what) {
  testing::expect_same_gl_mesh(gl, cpu, v, what);
}

// Every variant: both vertex variants, the three solvers, both Hermite choices; quads and normals
// on some. (Each variant is a set of programs compiled at run time, which llvmpipe takes a while
// over: the other tests reuse these.)
std::vector<DualContouringOptions> variants(double iso) {
  std::vector<DualContouringOptions> out;
  for (DcVertices vert : {DcVertices::Patch, DcVertices::Cell})
    for (DcSolver solver : {DcSolver::MassPoint, DcSolver::Particle, DcSolver::Qef})
      for (DcHermite hermite : {DcHermite::Central, DcHermite::Eno}) {
        DualContouringOptions o;
        o.iso = iso;
        o.vertices = vert;
        o.solver = solver;
        o.hermite = hermite;
        o.normals = solver != DcSolver::MassPoint;
        o.keep_quads = solver == DcSolver::MassPoint && hermite == DcHermite::Eno;
        out.push_back(o);
      }
  return out;
}

class GlDc : public ::testing::TestWithParam<Path> {};

// Odd dims, anisotropic spacing and an offset origin; Marschner-Lobb has many cells with several
// patches, flipped faces and cut border cells; csg-box has the sharp features ENO looks for.
TEST_P(GlDc, FieldsEqualCpuForEveryVariant) {
  REQUIRE_GL();
  for (const char* name : {"field:marschner-lobb:23", "field:csg-box:21"}) {
    const FieldSpec spec = *parse_field_spec(name);
    Volume vol = make_field_volume(spec);
    vol.set_spacing({0.5, 1.0, 2.0});
    vol.set_origin({-3.0, 0.25, 7.0});
    for (const DualContouringOptions& o : variants(field_default_iso(spec.kind))) {
      const Mesh cpu = dual_contouring(vol.view(), o);
      ASSERT_GT(cpu.triangles.size() + cpu.quads.size(), 100u) << name;
      expect_same_mesh(run(GetParam(), vol.view(), gl_options(o)), cpu, vol.view(),
                       std::string(name) + " " + describe(o));
    }
  }
}

// Samples exactly at the isovalue (pinned ties move their crossings, isovalue_ties.h), in every
// sample type, each uploaded as stored and widened by the shaders.
TEST_P(GlDc, TiesAndWideSamplesEqualCpu) {
  REQUIRE_GL();
  const Volume field = make_field_volume({FieldKind::Gyroid, 19});
  for (ScalarType t :
       {ScalarType::Int8, ScalarType::UInt8, ScalarType::Int16, ScalarType::UInt16,
        ScalarType::Int32, ScalarType::UInt32, ScalarType::Float32, ScalarType::Float64}) {
    Volume v(t, field.dims(), field.spacing(), field.origin());
    visit_scalar(t, [&](auto tag) {
      using T = decltype(tag);
      for (std::int64_t i = 0; i < field.sample_count(); ++i)
        v.data<T>()[i] = static_cast<T>(std::round(field.data<float>()[i] * 3.0 + 64.0));
    });
    DualContouringOptions o;
    o.iso = 64.0;
    o.solver = DcSolver::Particle;
    o.normals = true;
    const Mesh cpu = dual_contouring(v.view(), o);
    expect_same_mesh(run(GetParam(), v.view(), gl_options(o)), cpu, v.view(),
                     std::string(scalar_name(t)));
  }
}

// Random samples: ambiguous faces everywhere, so faces flip and cells hold several patches, and
// border cells are cut (dual_contouring_patches.h).
TEST_P(GlDc, NoiseEqualsCpu) {
  REQUIRE_GL();
  const Index3 dims{14, 11, 13};
  std::vector<std::uint8_t> noise(14 * 11 * 13);
  std::uint32_t state = 12345;
  for (auto& v : noise) {
    state = state * 1664525u + 1013904223u;
    v = static_cast<std::uint8_t>(state >> 24);
  }
  const VolumeView view = dense_view(noise.data(), ScalarType::UInt8, dims);
  ASSERT_GT(dual_contouring_patch_repairs(view, 127.5).flipped_faces, 0u);
  ASSERT_GT(dual_contouring_patch_repairs(view, 127.5).border_cut_cells, 0u);
  for (const DualContouringOptions& o :
       {variants(127.5)[0], variants(127.5)[4], variants(127.5)[6]}) {
    const Mesh cpu = dual_contouring(view, o);
    expect_same_mesh(run(GetParam(), view, gl_options(o)), cpu, view, "noise " + describe(o));
  }
}

// Slabs along z (a volume larger than the device's memory) give the whole-volume mesh.
TEST_P(GlDc, SlabsEqualWholeVolume) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Torus, 26});
  DualContouringOptions o;
  o.iso = field_default_iso(FieldKind::Torus);
  o.solver = DcSolver::Particle;
  o.normals = true;
  const Mesh cpu = dual_contouring(vol.view(), o);
  for (std::int64_t slab : {1, 4, 9}) {
    gl::McStats stats;
    const Mesh gl = run(GetParam(), vol.view(), gl_options(o, slab), &stats);
    EXPECT_EQ(stats.bricks, (25 + slab - 1) / slab);
    expect_same_mesh(gl, cpu, vol.view(), "slab " + std::to_string(slab));
  }
}

// Brick mode (the tiler's contract): a box of cells from a view holding it plus the halo equals
// the CPU's brick output, whole or in slabs, and bricks put together are the whole-volume mesh.
TEST_P(GlDc, BrickModeEqualsCpu) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::MarschnerLobb, 25});
  const VolumeView whole = vol.view();
  for (DcHermite hermite : {DcHermite::Central, DcHermite::Eno}) {
    DualContouringOptions base;
    base.iso = field_default_iso(FieldKind::MarschnerLobb);
    base.hermite = hermite;
    base.solver = DcSolver::Particle;
    base.normals = true;
    const int halo = dual_contouring_halo(base);
    for (const Box3& cells : {Box3{{0, 0, 0}, {1, 1, 1}}, Box3{{5, 3, 11}, {18, 20, 17}},
                              Box3{{16, 0, 15}, {24, 24, 24}}}) {
      Box3 local;
      for (int a = 0; a < 3; ++a) {
        local.lo[a] = std::max<std::int64_t>(cells.lo[a] - halo, 0);
        local.hi[a] = std::min<std::int64_t>(cells.hi[a] + halo + 1, whole.dims[a]);
      }
      const VolumeView view = subview(whole, local);
      DualContouringOptions o = base;
      o.cells = cells;
      const Mesh cpu = dual_contouring(view, o);
      for (std::int64_t slab : {0, 2})
        expect_same_mesh(run(GetParam(), view, gl_options(o, slab)), cpu, view, "brick");
    }
    testing::expect_bricks_equal_whole(whole,
                                       [&](const VolumeView& view, const Box3& cells) {
                                         DualContouringOptions o = base;
                                         o.cells = cells;
                                         return testing::KeyedMesh{
                                             run(GetParam(), view, gl_options(o)),
                                             dual_contouring_vertex_keys(view, o)};
                                       },
                                       halo, {9, 7, 11});
  }
  // A view without the halo is the CPU's error.
  DualContouringOptions o;
  o.cells = Box3{{5, 5, 5}, {9, 9, 9}};
  const VolumeView bare = subview(whole, Box3{{5, 5, 5}, {10, 10, 10}});
  EXPECT_THROW(run(GetParam(), bare, gl_options(o)), InputError);
}

// A crop of a real CT volume (../shared/data), default options and the paper's particle.
TEST_P(GlDc, RealVolumeEqualsCpu) {
  REQUIRE_GL();
  const auto path = shared_volume("neghip_66x66x66_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(path);
  const Volume vol = read_volume(path.string());
  const VolumeView crop = subview(vol.view(), Box3{{10, 12, 8}, {47, 50, 41}});
  for (double iso : {49.5, 100.0}) {
    DualContouringOptions o;
    o.iso = iso;
    const Mesh cpu = dual_contouring(crop, o);
    ASSERT_GT(cpu.triangles.size(), 1000u);
    expect_same_mesh(run(GetParam(), crop, gl_options(o)), cpu, crop, "neghip");
    o.solver = DcSolver::Particle;
    o.hermite = DcHermite::Eno;
    o.normals = true;
    expect_same_mesh(run(GetParam(), crop, gl_options(o)), dual_contouring(crop, o), crop,
                     "neghip particle eno");
  }
}

TEST_P(GlDc, EmptyAndTinyVolumes) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Sphere, 12});
  DualContouringOptions far;
  far.iso = 1e9;
  const Mesh none = run(GetParam(), vol.view(), gl_options(far));
  EXPECT_TRUE(none.positions.empty() && none.triangles.empty());
  // One cell: no face and no vertex (its edges lie on the border). Three cubed with the middle
  // inside: six quads round it.
  float one[8] = {1, 0, 0, 0, 0, 0, 0, 0};
  float middle[27] = {};
  middle[13] = 1;
  for (float* s : {one, middle}) {
    const Index3 d = s == one ? Index3{2, 2, 2} : Index3{3, 3, 3};
    const VolumeView tiny = dense_view(s, ScalarType::Float32, d);
    DualContouringOptions o;
    o.iso = 0.5;
    const Mesh cpu = dual_contouring(tiny, o);
    ASSERT_EQ(cpu.triangles.size(), s == one ? 0u : 12u);
    ASSERT_EQ(cpu.positions.size(), s == one ? 0u : 8u);
    expect_same_mesh(run(GetParam(), tiny, gl_options(o)), cpu, tiny, "tiny");
  }
}

// Invalid options are the CPU's errors.
TEST_P(GlDc, InvalidOptionsAreErrors) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Sphere, 12});
  DualContouringOptions o;
  o.particle_steps = -1;
  EXPECT_THROW(run(GetParam(), vol.view(), gl_options(o)), InputError);
  o.particle_steps = 10;
  o.particle_rate = 0;
  EXPECT_THROW(run(GetParam(), vol.view(), gl_options(o)), InputError);
}

INSTANTIATE_TEST_SUITE_P(Gl, GlDc, ::testing::Values(Path::Gs, Path::Hp),
                         [](const auto& info) { return info.param == Path::Gs ? "Gs" : "Hp"; });

// A capture buffer far too small: the geometry-shader path resumes at the cut element; the mesh
// is unchanged, triangles and quads alike.
TEST(GlDcGeometryShader, CaptureOverflowResumes) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 17});
  for (bool quads : {false, true}) {
    DualContouringOptions o;
    o.keep_quads = quads;
    o.hermite = quads ? DcHermite::Eno : DcHermite::Central;
    const Mesh cpu = dual_contouring(vol.view(), o);
    for (std::uint64_t bytes : {1u, 700u, 9000u}) {
      gl::McStats stats;
      gl::DcGlOptions g = gl_options(o, 7);
      g.capture_bytes = bytes;
      const Mesh gl = gl::dc_geometry_shader(vol.view(), g, &stats);
      EXPECT_GT(stats.capture_passes, stats.bricks) << bytes;
      expect_same_mesh(gl, cpu, vol.view(), "overflow " + std::to_string(bytes));
    }
  }
}

// Through core's backend table: both GL backends run dc; auto stays on the CPU on software GL.
TEST(GlDcBackends, RegisteredInTheTable) {
  REQUIRE_GL();
  gl::register_gl_backends();
  const Volume vol = make_field_volume({FieldKind::Sphere, 14});
  const Mesh cpu = dual_contouring(vol.view(), {});
  for (Backend b : {Backend::GeometryShader, Backend::HistoPyramid}) {
    const ExtractOptions o{.method = Method::DualContouring, .backend = b};
    EXPECT_EQ(resolve_backend(o), b);
    expect_same_mesh(extract(vol.view(), o), cpu, vol.view(), "table");
    for (const BackendCaps& c : capabilities())
      if (c.backend == b) {
        EXPECT_NE(std::find(c.methods.begin(), c.methods.end(), Method::DualContouring),
                  c.methods.end());
      }
  }
  const Backend a = resolve_backend({.method = Method::DualContouring});
  // Never a GL path on a software device; on a GPU whatever the rules say (the CPU everywhere
  // until a GL path is measured faster: kAutoRules).
  if (gl::device().software) {
    EXPECT_EQ(a, Backend::Cpu);
  }
}

}  // namespace
}  // namespace isotile
