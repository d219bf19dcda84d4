// With no usable OpenGL context (forced by ISOTILE_GL=off before any GL use), asking for a GL
// backend is one clear InputError, never a crash, and `auto` falls back to the CPU.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/volume/procedural_fields.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "shaders/hp_pyramid.h"

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

// Sets (or, with nullptr, unsets) an environment variable for its lifetime, then puts back what
// was there: the ctests that rerun these suites set some of them.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* was = std::getenv(name)) saved_ = was;
    set(value);
  }
  ~ScopedEnv() { set(saved_ ? saved_->c_str() : nullptr); }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;
  void set(const char* value) {
    if (value)
      setenv(name_, value, 1);
    else
      unsetenv(name_);
  }

 private:
  const char* name_;
  std::optional<std::string> saved_;
};

// Which GPU a process takes (gl::hardware_device_order(), from the environment only): the one
// ISOTILE_GL_DEVICE names, else from its launcher's node-local rank modulo the GPUs, else the
// first; every other device after it in turn.
TEST(HardwareDeviceOrder, NamedDeviceElseNodeLocalRankElseFirst) {
  ScopedEnv device("ISOTILE_GL_DEVICE", nullptr), ompi("OMPI_COMM_WORLD_LOCAL_RANK", nullptr),
      mpich("MPI_LOCALRANKID", nullptr), mvapich("MV2_COMM_WORLD_LOCAL_RANK", nullptr),
      slurm("SLURM_LOCALID", nullptr);

  gl::DeviceOrder o = gl::hardware_device_order(4);
  EXPECT_EQ(o.order, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(o.chosen_by, "first");
  EXPECT_TRUE(o.why.empty());
  EXPECT_TRUE(gl::hardware_device_order(0).order.empty());

  slurm.set("1");
  EXPECT_EQ(gl::hardware_device_order(4).order, (std::vector<int>{1, 2, 3, 0}));
  ompi.set("6");  // before Slurm's: mpirun inside an allocation
  o = gl::hardware_device_order(4);
  EXPECT_EQ(o.order, (std::vector<int>{2, 3, 0, 1}));
  EXPECT_EQ(o.chosen_by, "OMPI_COMM_WORLD_LOCAL_RANK=6");
  EXPECT_EQ(gl::hardware_device_order(1).order, (std::vector<int>{0}));
  ompi.set("x");  // not a rank: the next variable
  EXPECT_EQ(gl::hardware_device_order(4).chosen_by, "SLURM_LOCALID=1");

  device.set("3");  // named: that one only, whatever the rank
  o = gl::hardware_device_order(4);
  EXPECT_EQ(o.order, (std::vector<int>{3}));
  EXPECT_EQ(o.chosen_by, "ISOTILE_GL_DEVICE");
  o = gl::hardware_device_order(2);
  EXPECT_TRUE(o.order.empty());
  EXPECT_EQ(o.why, "ISOTILE_GL_DEVICE=3, but EGL lists 2 hardware devices (0 to 1)");
  for (const char* bad : {"-1", "1x", "one", " 1"}) {
    device.set(bad);
    o = gl::hardware_device_order(4);
    EXPECT_TRUE(o.order.empty()) << bad;
    EXPECT_NE(o.why.find("is not a device number"), std::string::npos) << o.why;
  }
}

// The environment's choices of pyramid passes and output design: the words they take, and one
// error naming the variable for anything else.
TEST(HpPassChoices, FromTheEnvironment) {
  ScopedEnv output("ISOTILE_HP_OUTPUT", nullptr), levels("ISOTILE_HP_LEVELS_PER_PASS", nullptr);
  EXPECT_EQ(gl::default_hp_output(), gl::HpOutput::Descend);
  output.set("descend");
  EXPECT_EQ(gl::default_hp_output(), gl::HpOutput::Descend);
  output.set("scatter");
  EXPECT_EQ(gl::default_hp_output(), gl::HpOutput::Scatter);
  for (const char* bad : {"Scatter", "scatter ", "1"}) {
    output.set(bad);
    try {
      gl::default_hp_output();
      ADD_FAILURE() << "ISOTILE_HP_OUTPUT=" << bad << " taken";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("ISOTILE_HP_OUTPUT"), std::string::npos) << e.what();
    }
  }
  for (const char* good : {"1", "2", "3"}) {
    levels.set(good);
    EXPECT_EQ(gl::default_levels_per_pass(), good[0] - '0');
  }
  for (const char* bad : {"0", "4", "33", "x"}) {
    levels.set(bad);
    EXPECT_THROW(gl::default_levels_per_pass(), InputError) << bad;
  }
}

}  // namespace
}  // namespace isotile
