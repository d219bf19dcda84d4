// Backend::Auto: one table of rules (core/extract/extract.cpp), the CPU on every machine until a
// GL path is measured faster, an override for diagnosis (ISOTILE_AUTO_BACKEND), and a backend
// that fails under Auto followed by the CPU: Auto never fails where the CPU would succeed.
#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/volume/procedural_fields.h"

namespace isotile {
namespace {

Mesh failing(const VolumeView&, const ExtractOptions&, GpuReport*) {
  throw Error("the device lost its context");
}
std::string runs_here(bool* hardware, bool) {
  *hardware = true;
  return "";
}

class AutoBackend : public ::testing::Test {
 protected:
  void TearDown() override { unsetenv("ISOTILE_AUTO_BACKEND"); }
  Volume volume_ = make_field_volume(*parse_field_spec("field:sphere:24"));
  ExtractOptions options_{.iso = field_default_iso(FieldKind::Sphere)};
};

TEST_F(AutoBackend, TakesTheCpuAndSaysWhy) {
  for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring}) {
    ExtractOptions o = options_;
    o.method = m;
    const BackendChoice c = choose_backend(o);
    EXPECT_EQ(c.backend, Backend::Cpu);
    EXPECT_NE(c.reason.find("auto: the CPU"), std::string::npos) << c.reason;
    o.backend = Backend::Cpu;
    EXPECT_EQ(choose_backend(o).reason, "requested");
  }
}

TEST_F(AutoBackend, AFailingBackendUnderAutoIsFollowedByTheCpu) {
  // A stand-in GPU backend that runs here but fails when asked to extract.
  register_backend(Backend::GeometryShader, {failing, failing, failing}, runs_here);
  setenv("ISOTILE_AUTO_BACKEND", "gs", 1);
  ExtractOptions cpu = options_;
  cpu.backend = Backend::Cpu;
  const Mesh reference = extract(volume_.view(), cpu);
  ASSERT_GT(reference.triangles.size(), 100u);

  EXPECT_EQ(choose_backend(options_).backend, Backend::GeometryShader);
  BackendChoice ran;
  testing::internal::CaptureStderr();
  const Mesh mesh = extract(volume_.view(), options_, &ran);
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(ran.backend, Backend::Cpu);
  EXPECT_NE(ran.reason.find("the device lost its context"), std::string::npos) << ran.reason;
  EXPECT_EQ(err,
            "isotile: warning: the gs backend failed (the device lost its context); extracting "
            "on the CPU instead\n");
  EXPECT_TRUE(mesh.positions == reference.positions);
  EXPECT_TRUE(mesh.triangles == reference.triangles);

  // A caller that hears the warnings itself gets the line, and stderr nothing.
  std::vector<std::string> said;
  ExtractOptions heard = options_;
  heard.warn = [&](const std::string& line) { said.push_back(line); };
  testing::internal::CaptureStderr();
  const Mesh again = extract(volume_.view(), heard);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(said, std::vector<std::string>{"the gs backend failed (the device lost its context); "
                                           "extracting on the CPU instead"});
  EXPECT_TRUE(again.triangles == reference.triangles);

  // Asked for by name, the same backend's failure is the caller's error.
  ExtractOptions gs = options_;
  gs.backend = Backend::GeometryShader;
  EXPECT_THROW(extract(volume_.view(), gs), Error);
}

TEST_F(AutoBackend, AnOverrideThatCannotRunGivesTheCpu) {
  setenv("ISOTILE_AUTO_BACKEND", "hp", 1);  // not registered in this program: not built in
  const BackendChoice c = choose_backend(options_);
  EXPECT_EQ(c.backend, Backend::Cpu);
  EXPECT_NE(c.reason.find("ISOTILE_AUTO_BACKEND=hp cannot run mc here"), std::string::npos)
      << c.reason;
  setenv("ISOTILE_AUTO_BACKEND", "gpu", 1);
  EXPECT_THROW(choose_backend(options_), InputError);
}

// The tiler's bricks each report; the run's report sums them by stage name (a stage a later part
// adds is appended), sums the bytes, upload seconds and programs, and keeps the process's context
// start-up and the cache's "off" reason once.
TEST(GpuReports, BricksAddUp) {
  GpuReport a;
  a.seconds = {{"upload", 0.5}, {"classify", 1.0}};
  a.upload_bytes = 100;
  a.upload_seconds = 0.5;
  a.context_seconds = 0.25;
  a.programs_loaded = 3;
  a.programs_compiled = 2;
  GpuReport b;
  b.seconds = {{"upload", 0.25}, {"classify", 2.0}, {"faces", 4.0}};
  b.upload_bytes = 50;
  b.upload_seconds = 0.25;
  b.context_seconds = 0.25;
  b.programs_rejected = 1;
  b.program_cache_off = "read-only folder";
  std::optional<GpuReport> total;
  accumulate_gpu_report(total, a);
  ASSERT_TRUE(total.has_value());
  EXPECT_EQ(total->upload_bytes, 100u);
  accumulate_gpu_report(total, b);
  const std::vector<std::pair<std::string, double>> seconds = {
      {"upload", 0.75}, {"classify", 3.0}, {"faces", 4.0}};
  EXPECT_EQ(total->seconds, seconds);
  EXPECT_EQ(total->upload_bytes, 150u);
  EXPECT_EQ(total->upload_seconds, 0.75);
  EXPECT_EQ(total->context_seconds, 0.25);
  EXPECT_EQ(total->programs_loaded, 3);
  EXPECT_EQ(total->programs_compiled, 2);
  EXPECT_EQ(total->programs_rejected, 1);
  EXPECT_EQ(total->program_cache_off, "read-only folder");
}

}  // namespace
}  // namespace isotile
