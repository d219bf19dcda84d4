// The GL backends through the `isotile` command line: --backend gs|hp write the CPU's file byte for
// byte, gl-info describes the device, and without a context (ISOTILE_GL=off) an explicit GL backend
// is one error line while auto runs on the CPU.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

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

// The program cache (shaders/program_cache.h) in a fresh XDG_CACHE_HOME: the first run compiles
// and writes every program, the second loads every one and compiles none; an entry cut short, one
// with a flipped byte and one whose binary format the driver does not know are each rejected and
// compiled again, and the run after that loads everything again. Every run writes the CPU's file
// byte for byte, and --stats reports the stages, the upload, the making of the programs and of
// the pinned buffers, and the context's start-up.
TEST_F(GlCli, ProgramCacheMissesHitsAndRecompilesCorruptEntries) {
  REQUIRE_GL_CLI();
  const fs::path xdg = dir_ / "xdg";
  const std::string env = "XDG_CACHE_HOME='" + xdg.string() + "'";
  const std::string in = "extract field:gyroid:40 -q --normals ";
  ASSERT_EQ(run(in + "--backend cpu -o cpu.ply --stats cpu.json").code, 0);
  const auto cpu_stats = nlohmann::json::parse(slurp(dir_ / "cpu.json"));
  EXPECT_FALSE(cpu_stats["seconds"].contains("gl"));
  EXPECT_TRUE(cpu_stats["upload_gbps"].is_null());
  EXPECT_TRUE(cpu_stats["gl_program_cache"].is_null());
  auto hp = [&](const std::string& name) {
    const Result r = run(in + "--backend hp -o " + name + ".ply --stats " + name + ".json", env);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err, "") << name;
    EXPECT_TRUE(slurp(dir_ / (name + ".ply")) == slurp(dir_ / "cpu.ply")) << name;
    return nlohmann::json::parse(slurp(dir_ / (name + ".json")));
  };
  const auto first = hp("first");
  const auto& c1 = first["gl_program_cache"];
  if (c1["state"] == "off")
    ISOTILE_SKIP(Gl, "the driver cannot save GL programs here: " << c1["off_because"]);
  EXPECT_EQ(c1["state"], "miss");
  const int programs = c1["compiled"].get<int>();
  EXPECT_GE(programs, 5);
  EXPECT_EQ(c1["loaded"], 0);
  std::vector<fs::path> entries;
  for (const auto& e : fs::directory_iterator(xdg / "isotile")) entries.push_back(e.path());
  std::sort(entries.begin(), entries.end());
  ASSERT_EQ(static_cast<int>(entries.size()), programs);  // no temporary file left
  for (const fs::path& e : entries) EXPECT_EQ(e.extension(), ".bin") << e;
  // The stages, the upload (40^3 float32 samples in one slab) and the context.
  for (const char* stage : {"upload", "prepare", "classify", "scan", "vertices", "faces",
                            "readback", "programs", "pinned", "context"})
    EXPECT_GE(first["seconds"]["gl"][stage].get<double>(), 0.0) << stage;
  EXPECT_GT(first["seconds"]["gl"]["classify"].get<double>(), 0.0);
  EXPECT_GT(first["seconds"]["gl"]["context"].get<double>(), 0.0);
  EXPECT_GT(first["seconds"]["gl"]["programs"].get<double>(), 0.0);  // compiled
  EXPECT_GT(first["seconds"]["gl"]["pinned"].get<double>(), 0.0);    // the staging made
  EXPECT_EQ(first["upload_bytes"], 40 * 40 * 40 * 4);
  EXPECT_GT(first["upload_gbps"].get<double>(), 0.0);

  const auto second = hp("second");
  EXPECT_EQ(second["gl_program_cache"]["state"], "hit");
  EXPECT_EQ(second["gl_program_cache"]["loaded"], programs);
  EXPECT_EQ(second["gl_program_cache"]["compiled"], 0);
  EXPECT_GT(second["seconds"]["gl"]["programs"].get<double>(), 0.0);  // loaded

  // Cut short; one byte of the binary flipped; a binary format the driver does not know.
  fs::resize_file(entries[0], fs::file_size(entries[0]) / 2);
  auto patch = [](const fs::path& p, std::size_t offset, char x) {
    std::fstream f(p, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(static_cast<std::streamoff>(offset));
    char c = 0;
    f.get(c);
    f.seekp(static_cast<std::streamoff>(offset));
    f.put(static_cast<char>(c ^ x));
  };
  patch(entries[1], fs::file_size(entries[1]) - 1, 0x5a);
  patch(entries[2], 8, 0x77);  // the header's format word
  const auto third = hp("third");
  EXPECT_EQ(third["gl_program_cache"]["state"], "partial");
  EXPECT_EQ(third["gl_program_cache"]["rejected"], 3);
  EXPECT_EQ(third["gl_program_cache"]["compiled"], 3);
  EXPECT_EQ(third["gl_program_cache"]["loaded"], programs - 3);
  const auto fourth = hp("fourth");
  EXPECT_EQ(fourth["gl_program_cache"]["state"], "hit");
  EXPECT_EQ(fourth["gl_program_cache"]["rejected"], 0);
}

// Out of core, --stats sums the bricks' GL reports: every stage, the bytes uploaded (each brick's
// samples with their halo: more than the volume's) and the upload rate; the CPU's run has none.
// With simplification the bricks go through the simplifying tiler, which reports them too.
TEST_F(GlCli, OutOfCoreStatsSumTheBricksGlReports) {
  REQUIRE_GL_CLI();
  const std::string in = "extract field:gyroid:40 -q --memory 256KiB ";
  ASSERT_EQ(run(in + "--backend cpu -o cpu.ply --stats cpu.json").code, 0);
  const auto cpu = nlohmann::json::parse(slurp(dir_ / "cpu.json"));
  EXPECT_GT(cpu["bricks"].get<int>(), 1);
  EXPECT_FALSE(cpu["seconds"].contains("gl"));
  EXPECT_TRUE(cpu["upload_bytes"].is_null());
  EXPECT_TRUE(cpu["gl_program_cache"].is_null());
  for (const std::string extra : {"", "--simplify 0.5 "}) {
    const Result r = run(in + extra + "--backend hp -o hp.ply --stats hp.json");
    ASSERT_EQ(r.code, 0) << r.err;
    const auto hp = nlohmann::json::parse(slurp(dir_ / "hp.json"));
    EXPECT_EQ(hp["backend"], "hp") << extra;
    EXPECT_GT(hp["bricks"].get<int>(), 1) << extra;
    for (const char* stage : {"upload", "prepare", "classify", "scan", "vertices", "faces",
                              "readback", "programs", "pinned", "context"})
      EXPECT_GE(hp["seconds"]["gl"][stage].get<double>(), 0.0) << stage << " " << extra;
    EXPECT_GT(hp["seconds"]["gl"]["classify"].get<double>(), 0.0) << extra;
    EXPECT_GT(hp["upload_bytes"].get<std::uint64_t>(), 40u * 40 * 40 * 4) << extra;
    EXPECT_GT(hp["upload_gbps"].get<double>(), 0.0) << extra;
    EXPECT_TRUE(hp["gl_program_cache"].is_object()) << extra;
    if (extra.empty()) {
      EXPECT_TRUE(slurp(dir_ / "hp.ply") == slurp(dir_ / "cpu.ply"));
    }
  }
}

// Several processes filling one empty cache at once (as MPI ranks do): each writes its entries
// through a temporary file renamed over the entry, so all succeed, no temporary file is left and
// a later run loads every entry.
TEST_F(GlCli, ProgramCacheWrittenByProcessesAtOnce) {
  REQUIRE_GL_CLI();
  const fs::path xdg = dir_ / "xdg";
  const std::string env = "XDG_CACHE_HOME='" + xdg.string() + "'";
  const std::string in = "extract field:torus:30 -q --backend hp ";
  // In the work directory (`cd` first, on its own: `cd && a &` would put only `a` there).
  std::string cmd = "cd '";  // appended, not concatenated: GCC 12's -Wrestrict
  cmd += dir_.string();
  cmd += "' || exit 1; ";
  for (int p = 0; p < 4; ++p) {
    const std::string n = std::to_string(p);
    cmd += "(";
    cmd += env;
    cmd += " '";
    cmd += ISOTILE_CLI;
    cmd += "' ";
    cmd += in;
    for (const std::string& part :
         {std::string("-o p"), n, std::string(".ply || echo failed > fail"), n,
          std::string(") & ")})
      cmd += part;
  }
  cmd += "wait";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  // The CPU's file (equal files that are all empty would prove nothing).
  ASSERT_EQ(run("extract field:torus:30 -q --backend cpu -o cpu.ply").code, 0);
  EXPECT_TRUE(slurp(dir_ / "p0.ply") == slurp(dir_ / "cpu.ply"));
  for (const char* p : {"0", "1", "2", "3"}) {
    EXPECT_FALSE(fs::exists(dir_ / (std::string("fail") + p))) << p;
    EXPECT_TRUE(slurp(dir_ / (std::string("p") + p + ".ply")) == slurp(dir_ / "p0.ply")) << p;
  }
  const Result r = run(in + "-o last.ply --stats last.json", env);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(slurp(dir_ / "last.json"));
  if (j["gl_program_cache"]["state"] == "off")
    ISOTILE_SKIP(
        Gl, "the driver cannot save GL programs here: " << j["gl_program_cache"]["off_because"]);
  EXPECT_EQ(j["gl_program_cache"]["state"], "hit");
  EXPECT_EQ(j["gl_program_cache"]["rejected"], 0);
  for (const auto& e : fs::directory_iterator(xdg / "isotile"))
    EXPECT_EQ(e.path().extension(), ".bin") << e.path();
}

// A cache folder that cannot be made is no error: one note, and the run compiles and succeeds.
// (Mesa keeps its own shader cache elsewhere here, so that the driver can still save programs.)
TEST_F(GlCli, UnwritableProgramCacheIsOneNote) {
  REQUIRE_GL_CLI();
  std::ofstream(dir_ / "not-a-folder") << "x";
  fs::create_directories(dir_ / "mesa");
  const std::string env = "XDG_CACHE_HOME='" + (dir_ / "not-a-folder").string() +
                          "' MESA_SHADER_CACHE_DIR='" + (dir_ / "mesa").string() + "'";
  ASSERT_EQ(run("extract field:gyroid:30 -q --backend cpu -o cpu.ply").code, 0);
  const Result r = run("extract field:gyroid:30 -q --backend hp -o hp.ply --stats hp.json", env);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(slurp(dir_ / "hp.ply") == slurp(dir_ / "cpu.ply"));
  const auto j = nlohmann::json::parse(slurp(dir_ / "hp.json"));
  if (j["gl_program_cache"]["state"] == "off")
    ISOTILE_SKIP(
        Gl, "the driver cannot save GL programs here: " << j["gl_program_cache"]["off_because"]);
  EXPECT_EQ(j["gl_program_cache"]["state"], "miss");
  const std::string note = "isotile: note: the GL program cache ";
  ASSERT_NE(r.err.find(note), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find(note, r.err.find(note) + 1), std::string::npos) << r.err;  // once
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

TEST_F(GlCli, GlInfoDescribesTheDevice) {
  REQUIRE_GL_CLI();
  const Result r = run("gl-info --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_FALSE(j["renderer"].get<std::string>().empty());
  EXPECT_EQ(j["version"].get<std::string>().rfind("4.", 0), 0u);
  EXPECT_EQ(j["backends"]["hp"].get<std::string>().rfind("available", 0), 0u);
  // auto takes a GPU path only on a real GPU (on a GPU: whatever the rules say).
  if (j["software"].get<bool>()) {
    EXPECT_EQ(j["auto"], "cpu");
  }
  // Device memory: a number of KiB where the driver says it, else null (never the -1 that stood
  // for "not told"; llvmpipe tells nothing).
  for (const char* key : {"memory_total_kib", "memory_free_kib"})
    EXPECT_TRUE(j[key].is_null() || j[key].get<std::int64_t>() > 0) << key << ": " << j[key];
  // Which GPU, of how many and why: only on EGL's device platform.
  if (j["platform"] == "egl-device") {
    EXPECT_NE(j["egl_device"].get<std::string>().find(" of "), std::string::npos)
        << j["egl_device"];
  } else {
    EXPECT_TRUE(j["egl_device"].is_null()) << j["egl_device"];
  }
  // Where the program cache is, or why it is off.
  const fs::path xdg = dir_ / "xdg";
  const Result c = run("gl-info --json", "XDG_CACHE_HOME='" + xdg.string() + "'");
  ASSERT_EQ(c.code, 0) << c.err;
  const auto cache = nlohmann::json::parse(c.out);
  if (cache["program_binary_formats"].get<int>() > 0)
    EXPECT_EQ(cache["program_cache"], (xdg / "isotile").string());
  else
    EXPECT_EQ(cache["program_cache"].get<std::string>().rfind("off: the driver cannot save", 0), 0u)
        << cache["program_cache"];
  const Result off = run("gl-info --json", "ISOTILE_PROGRAM_CACHE=off");
  ASSERT_EQ(off.code, 0) << off.err;
  EXPECT_EQ(nlohmann::json::parse(off.out)["program_cache"].get<std::string>().rfind(
                "off: turned off by ISOTILE_PROGRAM_CACHE=off", 0),
            0u)
      << off.out;
}

TEST_F(GlCli, NoContextIsOneErrorLine) {
  // `args` under `env` exits 1 with one line on stderr starting with `error` and writes no file.
  auto expect_one_error_line = [&](const std::string& args, const std::string& env,
                                   const std::string& error) {
    const Result r = run(args + " -o m.ply", env);
    EXPECT_EQ(r.code, 1) << args << " " << env;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_EQ(r.err.rfind("isotile: error: " + error, 0), 0u) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "m.ply"));
  };
  for (const std::string b : {"gs", "hp"}) {
    expect_one_error_line("extract field:sphere:16 --backend " + b, "ISOTILE_GL=off",
                          "backend '" + b + "': no OpenGL context");
    // A context that fails while the volume is read (it is made on a thread of its own from the
    // start, gl::start_context()): the same one line, in core and out of core.
    for (const std::string memory : {"", " --memory 1MiB"})
      expect_one_error_line(
          "extract field:sphere:40 -q --backend " + b + memory, "ISOTILE_GL=nowhere",
          "backend '" + b + "': no usable OpenGL 4.5 context (ISOTILE_GL='nowhere' names no way");
  }
  // A GPU named by number that is not there: that GPU or nothing, never llvmpipe instead.
  expect_one_error_line("extract field:sphere:16 -q --backend hp", "ISOTILE_GL_DEVICE=99",
                        "backend 'hp': no usable OpenGL 4.5 context (device: "
                        "ISOTILE_GL_DEVICE=99, but EGL lists ");
  // What Mesa 22.3's OSMesa dies of SIGSEGV on, refused with the variable's name: a Gallium
  // driver it does not have, a GLSL version override below 140.
  expect_one_error_line("extract field:sphere:16 -q --backend hp",
                        "ISOTILE_GL=osmesa GALLIUM_DRIVER=nosuchdriver",
                        "backend 'hp': no usable OpenGL 4.5 context (osmesa: "
                        "GALLIUM_DRIVER='nosuchdriver' names no driver OSMesa has");
  expect_one_error_line("extract field:sphere:16 -q --backend hp",
                        "ISOTILE_GL=osmesa MESA_GLSL_VERSION_OVERRIDE=130",
                        "backend 'hp': no usable OpenGL 4.5 context (osmesa: "
                        "MESA_GLSL_VERSION_OVERRIDE=130 is below the GLSL 4.50");
  const Result a = run("extract field:sphere:16 -q -o m.ply --stats s.json", "ISOTILE_GL=off");
  ASSERT_EQ(a.code, 0) << a.err;
  EXPECT_EQ(nlohmann::json::parse(slurp(dir_ / "s.json"))["backend"], "cpu");
  const Result info = run("gl-info", "ISOTILE_GL=off");
  EXPECT_EQ(info.code, 1);
  EXPECT_NE(info.err.find("ISOTILE_GL=off"), std::string::npos) << info.err;
}

}  // namespace
