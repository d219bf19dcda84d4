// With no usable OpenGL context (forced by ISOTILE_GL=off before any GL use), asking for a GL
// backend is one clear InputError, never a crash, and `auto` falls back to the CPU.
#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/volume/procedural_fields.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"

namespace isotile {
namespace {

class NoContext : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    setenv("ISOTILE_GL", "off", 1);
    gl::register_gl_backends();
  }
};

TEST_F(NoContext, ExplicitGlBackendIsAClearError) {
  const Volume vol = make_field_volume({FieldKind::Sphere, 12});
  std::string why;
  EXPECT_FALSE(gl::available(&why));
  EXPECT_NE(why.find("ISOTILE_GL=off"), std::string::npos) << why;
  for (Backend b : {Backend::GeometryShader, Backend::HistoPyramid}) {
    try {
      extract(vol.view(), {.backend = b});
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("no OpenGL context"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(gl::mc_histopyramid(vol.view(), {}), InputError);
  EXPECT_THROW(gl::mc_geometry_shader(vol.view(), {}), InputError);
  EXPECT_THROW(gl::device(), InputError);
}

TEST_F(NoContext, AutoFallsBackToCpu) {
  EXPECT_EQ(resolve_backend({}), Backend::Cpu);
  for (const BackendCaps& c : capabilities())
    if (c.backend != Backend::Cpu) {
      EXPECT_FALSE(c.available);
      EXPECT_FALSE(c.why_unavailable.empty());
    }
}

}  // namespace
}  // namespace isotile
