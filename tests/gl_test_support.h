// What the GL extractor tests share: the skip when no context can be made, and the comparison of
// a GL mesh with the CPU's (the GL paths promise the CPU's mesh: docs/gl.md).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/volume/volume.h"
#include "shaders/gl_context.h"
#include "shaders/gl_variants.h"
#include "skip_support.h"

namespace isotile::testing {

// The OSMesa runs (ISOTILE_GL=osmesa, tests/CMakeLists.txt) need OSMesa, the others any context.
inline bool forcing_osmesa() {
  const char* env = std::getenv("ISOTILE_GL");
  return env && std::string(env) == "osmesa";
}

#define REQUIRE_GL()                                                                     \
  do {                                                                                   \
    std::string why;                                                                     \
    if (!::isotile::gl::available(&why)) {                                               \
      if (::isotile::testing::forcing_osmesa()) ISOTILE_SKIP(Osmesa, "OSMesa: " << why); \
      ISOTILE_SKIP(Gl, why);                                                             \
    }                                                                                    \
  } while (0)

enum class GlPath { Gs, Hp };

// The same vertex count, the same triangles and quads in the same order as the CPU, and the
// same positions and normals bit for bit, on every device: the shaders' double arithmetic is the
// CPU's where the device rounds `/`, `precise` products and sums correctly and sqrt_rn() gives
// std::sqrt's roots (gl_double_check). A failure says how many coordinates differ and by how much
// at most (positions in voxels).
inline void expect_same_gl_mesh(const Mesh& gl, const Mesh& cpu, const VolumeView& v,
                                const std::string& what) {
  ASSERT_EQ(gl.positions.size(), cpu.positions.size()) << what;
  ASSERT_EQ(gl.normals.size(), cpu.normals.size()) << what;
  ASSERT_EQ(gl.triangles.size(), cpu.triangles.size()) << what;
  ASSERT_EQ(gl.quads.size(), cpu.quads.size()) << what;
  EXPECT_TRUE(gl.triangles == cpu.triangles) << what;
  EXPECT_TRUE(gl.quads == cpu.quads) << what;
  std::size_t differ = 0;
  double worst = 0;
  for (std::size_t i = 0; i < cpu.positions.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      const double d = std::abs(double(gl.positions[i][a]) - double(cpu.positions[i][a]));
      worst = std::max(worst, d / v.spacing[a]);
      differ += gl.positions[i][a] != cpu.positions[i][a];
    }
  EXPECT_EQ(differ, 0u) << what << ": position coordinates differ, by up to " << worst << " voxel";
  std::size_t differ_n = 0;
  double worst_n = 0;
  for (std::size_t i = 0; i < cpu.normals.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      worst_n = std::max(worst_n, std::abs(double(gl.normals[i][a]) - double(cpu.normals[i][a])));
      differ_n += gl.normals[i][a] != cpu.normals[i][a];
    }
  EXPECT_EQ(differ_n, 0u) << what << ": normal coordinates differ, by up to " << worst_n;
}

// At the end of a GL test program: every program it built is one of the table's variants
// (shaders/gl_variants.h), which tests/test_glsl_variants.cpp checks with glslang. A driver that
// builds a program the table does not list fails here.
class BuiltProgramsListed : public ::testing::Environment {
 public:
  void TearDown() override {
    std::vector<std::string> listed;
    for (const gl::ProgramVariant& v : gl::program_variants())
      listed.push_back(gl::program_key(v.stages, v.defines));
    int built = 0;
    for (const std::string& key : gl::built_program_keys()) {
      ++built;
      if (std::find(listed.begin(), listed.end(), key) == listed.end())
        ADD_FAILURE() << "a GL test built a program that gl::program_variants() does not list: "
                      << key;
    }
    std::printf("gl_test_support: %d programs built, each listed in gl::program_variants()\n",
                built);
    // The GL test programs end as the CLI does: the context and its objects deleted, in order,
    // before exit (under OSMesa, LeakSanitizer's tracer sometimes crashed at exit among
    // llvmpipe's threads of a context left alive).
    gl::shutdown();
  }
};
inline ::testing::Environment* const kBuiltProgramsListed =
    ::testing::AddGlobalTestEnvironment(new BuiltProgramsListed);

}  // namespace isotile::testing
