// The GL backends through the `isotile` command line: --backend gs|hp write the CPU's file byte for
// byte, gl-info describes the device, and without a context (ISOTILE_GL=off) an explicit GL backend
// is one error line while auto runs on the CPU.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "cli_support.h"

namespace {

namespace fs = std::filesystem;

using Result = isotile::testing::CliResult;
using isotile::testing::slurp;

class GlCli : public isotile::testing::CliTest {
 protected:
  Result gl_info() { return run("gl-info"); }
};

// A broken `gl-info` alone must not turn these into skips where GL is demanded.
#define REQUIRE_GL_CLI()                                                                   \
  do {                                                                                     \
    const Result info = gl_info();                                                         \
    if (info.code != 0) ISOTILE_SKIP(Gl, "isotile gl-info found no OpenGL: " << info.err); \
  } while (0)

TEST_F(GlCli, GlBackendsWriteTheCpuFile) {
  REQUIRE_GL_CLI();
  for (const char* b : {"cpu", "gs", "hp"}) {
    const Result r = run(std::string("extract field:gyroid:40 --normals -q --backend ") + b +
                         " -o " + b + ".ply --stats " + b + ".json");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / (std::string(b) + ".json")))["backend"], b);
  }
  const std::string cpu = slurp(dir_ / "cpu.ply");
  EXPECT_GT(cpu.size(), 10000u);
  EXPECT_TRUE(slurp(dir_ / "gs.ply") == cpu);
  EXPECT_TRUE(slurp(dir_ / "hp.ply") == cpu);
}

// The tiler drives the GL backends brick by brick; the streamed file is the in-core CPU file.
TEST_F(GlCli, BrickedGlRunsWriteTheCpuFile) {
  REQUIRE_GL_CLI();
  ASSERT_EQ(run("extract field:torus:40 --normals -q --backend cpu -o cpu.ply").code, 0);
  for (const char* b : {"gs", "hp"}) {
    const Result r = run(std::string("extract field:torus:40 --normals -q --memory 60KiB ") +
                         "--backend " + b + " -o " + b + ".ply --stats " + b + ".json");
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = nlohmann::json::parse(slurp(dir_ / (std::string(b) + ".json")));
    EXPECT_EQ(j["backend"], b);
    EXPECT_GT(j["bricks"].get<int>(), 8);
    EXPECT_TRUE(slurp(dir_ / (std::string(b) + ".ply")) == slurp(dir_ / "cpu.ply")) << b;
  }
}

// A bricked GL run at many threads (TBB's workers drive the bricks) exits 0 with the CPU's file
// and leaves no GL or EGL object for the drivers' exit handlers: tests/gl_exit_check.c, preloaded,
// counts what is alive after everything else at exit and exits 3 when anything is. NVIDIA's libEGL
// corrupted the heap at exit when the context was left alive with TBB's workers running.
TEST_F(GlCli, BrickedGlRunsAtManyThreadsLeaveNothingAliveAtExit) {
  REQUIRE_GL_CLI();
  const std::string in = "--threads 8 extract field:gyroid:48 -q --memory 120KiB ";
  ASSERT_EQ(run(in + "--backend cpu -o cpu.ply").code, 0);
  const std::string preload = std::string("LD_PRELOAD='") + ISOTILE_GL_EXIT_CHECK +
                              "' ASAN_OPTIONS=\"$ASAN_OPTIONS:verify_asan_link_order=0\"";
  for (const char* b : {"hp", "gs"}) {
    const Result r =
        run(in + "--backend " + b + " -o " + b + ".ply --stats " + b + ".json", preload);
    EXPECT_EQ(r.code, 0) << b << ": " << r.err;
    EXPECT_NE(r.err.find("gl_exit_check: nothing alive at exit: 0 EGL contexts (of 1 made)"),
              std::string::npos)
        << b << ": " << r.err;
    EXPECT_GT(nlohmann::json::parse(slurp(dir_ / (std::string(b) + ".json")))["bricks"].get<int>(),
              4);
    EXPECT_TRUE(slurp(dir_ / (std::string(b) + ".ply")) == slurp(dir_ / "cpu.ply")) << b;
  }
  // Every subcommand that may touch GL ends the same way.
  const Result info = run("gl-info", preload);
  EXPECT_EQ(info.code, 0) << info.err;
  EXPECT_NE(info.err.find("gl_exit_check: nothing alive at exit"), std::string::npos) << info.err;
}

// Dual Contouring on both GL backends, in core and brick by brick through the tiler, writes the
// in-core CPU file, with the default options and with the QEF.
TEST_F(GlCli, DualContouringWritesTheCpuFile) {
  REQUIRE_GL_CLI();
  const std::string in = "extract field:marschner-lobb:30 --method dc -q ";
  ASSERT_EQ(run(in + "--backend cpu -o cpu.ply").code, 0);
  const std::string cpu = slurp(dir_ / "cpu.ply");
  EXPECT_GT(cpu.size(), 10000u);
  for (const char* b : {"gs", "hp"}) {
    const std::string name = std::string(b) + ".ply";
    ASSERT_EQ(run(in + "--backend " + b + " -o " + name).code, 0);
    EXPECT_TRUE(slurp(dir_ / name) == cpu) << b;
    const Result r =
        run(in + "--memory 40KiB --backend " + b + " -o tiled_" + name + " --stats s.json");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_GT(nlohmann::json::parse(slurp(dir_ / "s.json"))["bricks"].get<int>(), 8);
    EXPECT_TRUE(slurp(dir_ / ("tiled_" + name)) == cpu) << b;
  }
  // The QEF solver (Jacobi sweeps on both sides) with ENO Hermite data, kept quads, normals.
  const std::string qef = in + "--dc-solver qef --dc-hermite eno --quads --normals ";
  ASSERT_EQ(run(qef + "--backend cpu -o qef_cpu.ply").code, 0);
  for (const char* b : {"gs", "hp"}) {
    const std::string name = std::string("qef_") + b + ".ply";
    ASSERT_EQ(run(qef + "--backend " + b + " -o " + name).code, 0);
    EXPECT_TRUE(slurp(dir_ / name) == slurp(dir_ / "qef_cpu.ply")) << b;
  }
}

// Macet on the GL backends, in core and brick by brick through the tiler (Fast with normals, and
// Max with relaxation, whose search runs on the CPU between the GL passes; Max's halo of 139
// samples makes bricks of a small volume as slow as the whole, so Max runs in core here and in
// slabs in test_gl_macet): the CPU's file.
TEST_F(GlCli, MacetGlRunsWriteTheCpuFile) {
  REQUIRE_GL_CLI();
  for (const std::string m : {"--normals", "--quality max --macet-relax 0.3"}) {
    const bool max = m.find("max") != std::string::npos;
    const std::string base = "extract field:torus:24 --method macet -q " + m;
    ASSERT_EQ(run(base + " --backend cpu -o cpu.ply").code, 0);
    const std::string cpu = slurp(dir_ / "cpu.ply");
    EXPECT_GT(cpu.size(), 10000u);
    for (const char* b : {"gs", "hp"})
      for (const char* memory : {"", " --memory 60KiB"}) {
        if (max && *memory) continue;
        const Result r = run(base + memory + " --backend " + b + " -o gl.ply --stats gl.json");
        ASSERT_EQ(r.code, 0) << r.err;
        const auto j = nlohmann::json::parse(slurp(dir_ / "gl.json"));
        EXPECT_EQ(j["backend"], b);
        if (*memory) {
          EXPECT_GT(j["bricks"].get<int>(), 1) << m << " " << b;
        }
        EXPECT_TRUE(slurp(dir_ / "gl.ply") == cpu) << m << " " << b << memory;
      }
  }
}

TEST_F(GlCli, GlInfoDescribesTheDevice) {
  REQUIRE_GL_CLI();
  const Result r = run("gl-info --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_FALSE(j["renderer"].get<std::string>().empty());
  EXPECT_EQ(j["version"].get<std::string>().rfind("4.", 0), 0u);
  EXPECT_EQ(j["backends"]["hp"].get<std::string>().rfind("available", 0), 0u);
  // auto takes a GPU path only on a real GPU.
  EXPECT_EQ(j["auto"] == "cpu", j["software"].get<bool>());
}

TEST_F(GlCli, NoContextIsOneErrorLine) {
  for (const char* b : {"gs", "hp"}) {
    const Result r =
        run(std::string("extract field:sphere:16 --backend ") + b + " -o m.ply", "ISOTILE_GL=off");
    EXPECT_EQ(r.code, 1);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(r.err.rfind(std::string("isotile: error: backend '") + b + "': no OpenGL context", 0),
              0u)
        << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "m.ply"));
  }
  const Result a = run("extract field:sphere:16 -q -o m.ply --stats s.json", "ISOTILE_GL=off");
  ASSERT_EQ(a.code, 0) << a.err;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "s.json"))["backend"], "cpu");
  const Result info = run("gl-info", "ISOTILE_GL=off");
  EXPECT_EQ(info.code, 1);
  EXPECT_NE(info.err.find("ISOTILE_GL=off"), std::string::npos) << info.err;
}

}  // namespace
