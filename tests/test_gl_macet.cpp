// Macet on the OpenGL paths (geometry shader, HistoPyramid) against the CPU reference
// (core/extract/macet.h): the same triangles and vertex order, positions within 1e-4 voxel, for
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
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "shaders/macet_gl.h"
#include "test_support.h"

namespace isotile {
namespace {

using testing::shared_volume;

#define REQUIRE_GL()            \
  do {                          \
    std::string why;            \
    if (!gl::available(&why)) { \
      ISOTILE_SKIP(Gl, why);    \
    }                           \
  } while (0)

enum class Path { Gs, Hp };

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

// Same triangles and vertex order as the CPU; positions and normals within 1e-4 (voxels for
// positions). On llvmpipe (IEEE doubles) the positions are expected bit-equal.
void expect_same_mesh(const Mesh& gl, const Mesh& cpu, const VolumeView& v,
                      const std::string& what) {
  ASSERT_EQ(gl.positions.size(), cpu.positions.size()) << what;
  ASSERT_EQ(gl.normals.size(), cpu.normals.size()) << what;
  ASSERT_EQ(gl.triangles.size(), cpu.triangles.size()) << what;
  EXPECT_TRUE(gl.triangles == cpu.triangles) << what;
  std::size_t differ = 0;
  double worst = 0;
  for (std::size_t i = 0; i < cpu.positions.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      const double d = std::abs(double(gl.positions[i][a]) - double(cpu.positions[i][a]));
      worst = std::max(worst, d / v.spacing[a]);
      differ += gl.positions[i][a] != cpu.positions[i][a];
    }
  EXPECT_LE(worst, 1e-4) << what;
  if (gl::device().software) {
    EXPECT_EQ(differ, 0u) << what;
  }
  double worst_n = 0;
  for (std::size_t i = 0; i < cpu.normals.size(); ++i)
    for (int a = 0; a < 3; ++a)
      worst_n = std::max(worst_n, std::abs(double(gl.normals[i][a]) - double(cpu.normals[i][a])));
  EXPECT_LE(worst_n, 1e-4) << what;
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

INSTANTIATE_TEST_SUITE_P(Gl, GlMacet, ::testing::Values(Path::Gs, Path::Hp),
                         [](const auto& info) { return info.param == Path::Gs ? "Gs" : "Hp"; });

}  // namespace
}  // namespace isotile
