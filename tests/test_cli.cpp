// The isotile command line as scripts use it: exit codes, one-line errors, stats JSON keys, and
// that a failure never leaves a partial or clobbered output behind.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "cli_support.h"
#include "core/extract/dual_contouring.h"
#include "core/mesh/mesh_io.h"
#include "core/version.h"
#include "core/volume/volume_io.h"

namespace fs = std::filesystem;

namespace {

using Result = isotile::testing::CliResult;
using isotile::testing::slurp;

class Cli : public isotile::testing::CliTest {};

int count_of(const std::string& s, const std::string& what) {
  int n = 0;
  for (auto pos = s.find(what); pos != std::string::npos; pos = s.find(what, pos + 1)) ++n;
  return n;
}

std::string last_line(std::string s) {
  while (!s.empty() && s.back() == '\n') s.pop_back();
  const auto nl = s.rfind('\n');
  return nl == std::string::npos ? s : s.substr(nl + 1);
}

// --version is the library's version (one definition, core/version.h), which a program linked
// against the library can ask for.
TEST_F(Cli, VersionIsTheLibrarys) {
  const Result r = run("--version");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out, "isotile " + std::string(isotile::version()) + "\n");
  EXPECT_EQ(std::count(isotile::version().begin(), isotile::version().end(), '.'), 2);
}

TEST_F(Cli, HelpForEverySubcommand) {
  for (const char* sub : {"", "extract ", "info ", "quality ", "demo "}) {
    const Result r = run(std::string(sub) + "--help");
    EXPECT_EQ(r.code, 0) << sub;
    EXPECT_NE(r.out.find("Usage"), std::string::npos) << sub;
  }
  EXPECT_NE(run("extract --help").out.find("--iso"), std::string::npos);
}

TEST_F(Cli, ExtractWritesMeshAndStatsWithTheDocumentedKeys) {
  const Result r = run("extract field:sphere:40 -o s.ply --stats s.json --quiet");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << "--quiet printed: " << r.err;
  const auto j = nlohmann::json::parse(slurp(dir_ / "s.json"));
  for (const char* key :
       {"triangles", "vertices", "radius_ratio_min", "radius_ratio_mean", "radius_ratio_q001",
        "radius_ratio_q01", "boundary_edges", "nonmanifold_edges", "euler", "watertight", "bricks",
        "seconds", "peak_rss_mb", "distance_mean", "distance_max"})
    EXPECT_TRUE(j.contains(key)) << key;
  for (const char* key : {"read", "extract", "write", "total"})
    EXPECT_TRUE(j["seconds"].contains(key)) << key;
  EXPECT_EQ(j["euler"], 2);
  EXPECT_EQ(j["watertight"], true);
  EXPECT_EQ(j["boundary_edges"], 0);
  EXPECT_LT(j["distance_max"].get<double>(), 0.1);
  EXPECT_GT(j["radius_ratio_mean"].get<double>(), 0.5);
  const isotile::Mesh m = isotile::read_mesh(dir_ / "s.ply");
  EXPECT_EQ(m.triangles.size(), j["triangles"].get<std::size_t>());
  EXPECT_EQ(m.positions.size(), j["vertices"].get<std::size_t>());
}

TEST_F(Cli, ProgressGoesToStderrAndStatsToStdout) {
  const Result r = run("extract field:torus:24 -o t.obj --stats -");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("extracted"), std::string::npos);
  EXPECT_EQ(nlohmann::json::parse(r.out)["euler"], 0);
}

TEST_F(Cli, SameOutputBytesForAnyThreadCount) {
  ASSERT_EQ(run("--threads 1 extract field:gyroid:90 -o a.ply --normals -q").code, 0);
  ASSERT_EQ(run("--threads 2 extract field:gyroid:90 -o b.ply --normals -q").code, 0);
  ASSERT_EQ(run("--threads 8 extract field:gyroid:90 -o c.ply --normals -q").code, 0);
  const std::string a = slurp(dir_ / "a.ply");
  EXPECT_GT(a.size(), 100000u);
  EXPECT_EQ(a, slurp(dir_ / "b.ply"));
  EXPECT_EQ(a, slurp(dir_ / "c.ply"));
}

TEST_F(Cli, DualContouringKeepsOrSplitsQuads) {
  Result r = run("extract field:sphere:32 --method dc -q -o s.ply --stats -");
  ASSERT_EQ(r.code, 0) << r.err;
  auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["method"], "dc");
  EXPECT_EQ(j["euler"], 2);
  EXPECT_EQ(j["closed"], true);
  const isotile::Mesh split = isotile::read_mesh(dir_ / "s.ply");
  EXPECT_TRUE(split.quads.empty());
  r = run("extract field:sphere:32 --method dc --dc-solver particle --quads -q -o q.ply --stats -");
  ASSERT_EQ(r.code, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  const isotile::Mesh quads = isotile::read_mesh(dir_ / "q.ply");
  EXPECT_TRUE(quads.triangles.empty());
  EXPECT_EQ(2 * quads.quads.size(), split.triangles.size());
  EXPECT_EQ(j["triangles"].get<std::size_t>(), split.triangles.size());
}

// The in-core run frees the samples before writing; the repairs its stats report must still be
// counted from them, before that.
TEST_F(Cli, DualContouringRepairsAreCountedFromTheSamples) {
  const int n = 24;
  std::string bytes(static_cast<std::size_t>(n) * n * n, '\0');
  unsigned state = 12345;
  for (char& c : bytes) {
    state = state * 1103515245u + 12345u;
    c = static_cast<char>((state >> 16) & 0xff);
  }
  const std::string name = "noise_24x24x24_uint8.raw";
  std::ofstream(dir_ / name, std::ios::binary) << bytes;
  const isotile::Volume volume = isotile::read_volume((dir_ / name).string());
  const isotile::DcPatchRepairs expected =
      isotile::dual_contouring_patch_repairs(volume.view(), 127.5);
  ASSERT_GT(expected.flipped_faces, 0u);
  ASSERT_GT(expected.border_cut_cells, 0u);
  const Result r = run("extract " + name + " --iso 127.5 --method dc -q -o n.ply --stats -");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["dc_flipped_faces"].get<std::uint64_t>(), expected.flipped_faces);
  EXPECT_EQ(j["dc_border_cut_cells"].get<std::uint64_t>(), expected.border_cut_cells);
}

TEST_F(Cli, MacetReportsItsQualityMode) {
  for (const char* mode : {"fast", "max"}) {
    Result r = run(std::string("extract field:torus:32 --method macet --quality ") + mode +
                   " -q -o t.ply --stats -");
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["method"], "macet");
    EXPECT_EQ(j["quality"], mode);
    EXPECT_EQ(j["euler"], 0);
    EXPECT_EQ(j["closed"], true);
  }
  Result r = run("extract field:torus:32 --method macet --macet-relax 0.3 -q -o t.ply --stats -");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["macet_relax"], 0.3);
  r = run("extract field:torus:32 -q -o t.ply --stats -");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(nlohmann::json::parse(r.out).contains("quality"));
  EXPECT_FALSE(nlohmann::json::parse(r.out).contains("macet_relax"));
}

TEST_F(Cli, EveryFormatIsWritten) {
  for (const char* name : {"m.ply", "m.obj", "m.stl", "m.off"}) {
    ASSERT_EQ(run(std::string("extract field:csg-box:20 -q -o ") + name).code, 0) << name;
    EXPECT_GT(isotile::read_mesh(dir_ / name).triangles.size(), 100u) << name;
  }
}

TEST_F(Cli, ErrorsAreOneLineAndLeaveNoFiles) {
  struct Bad {
    std::string args;
    std::string says;
  };
  {
    std::ofstream raw(dir_ / "short_4x4x4_uint8.raw", std::ios::binary);
    raw << "only a few bytes";
    std::ofstream plain(dir_ / "short.raw", std::ios::binary);
    plain << "a raw file whose name says nothing";
    std::ofstream gz(dir_ / "bad_4x4x4_uint8.raw.gz", std::ios::binary);
    gz << "plain text, no compression header at all";
  }
  const Bad cases[] = {
      {"extract missing_8x8x8_uint8.raw --iso 1 -o out.ply", "missing_8x8x8_uint8.raw"},
      {"extract short_4x4x4_uint8.raw --iso 1 -o out.ply", "short"},
      {"extract bad_4x4x4_uint8.raw.gz --iso 1 -o out.ply", "not gzip"},
      {"extract field:sphere:16 -o out.xyz", ".xyz"},
      {"extract field:sphere:16 -o no_such_dir/out.ply", "no_such_dir"},
      {"extract field:blob:16 -o out.ply", "blob"},
      {"extract field:sphere:1 -o out.ply", "field"},
      {"extract short_4x4x4_uint8.raw -o out.ply", "--iso"},
      {"extract short.raw --iso 1 -o out.ply", "--dims"},
      {"extract short.raw --iso 1 --dims 4,4 --type uint8 -o out.ply", "--dims"},
      {"extract short.raw --iso 1 --dims 4,4,4 --type uint9 -o out.ply", "uint9"},
      {"extract field:sphere:16 --macet-relax 0.2 -o out.ply", "--macet-relax"},
      {"quality missing.ply", "missing.ply"},
      {"info missing.nrrd", "missing.nrrd"},
  };
  for (const Bad& b : cases) {
    const Result r = run(b.args);
    EXPECT_EQ(r.code, 1) << b.args << "\n" << r.err;
    // Progress lines may come first; the error is one line, the last.
    const std::string last = last_line(r.err);
    EXPECT_EQ(count_of(r.err, "error"), 1) << b.args << "\n" << r.err;
    EXPECT_EQ(last.rfind("isotile: error: ", 0), 0u) << b.args << "\n" << r.err;
    EXPECT_NE(last.find(b.says), std::string::npos) << b.args << "\n" << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << b.args;
    EXPECT_EQ(stray_files({"short_4x4x4_uint8.raw", "short.raw", "bad_4x4x4_uint8.raw.gz"}),
              std::vector<std::string>{})
        << b.args;
  }
}

TEST_F(Cli, UsageErrorsExitWithTwo) {
  EXPECT_EQ(run("").code, 2);
  EXPECT_EQ(run("frobnicate").code, 2);
  EXPECT_EQ(run("extract field:sphere:16").code, 2);  // no -o
  EXPECT_EQ(run("extract field:sphere:16 --method macet --macet-relax 0.5 -o a.ply").code, 2);
  EXPECT_EQ(run("extract field:sphere:16 --method macet --macet-relax x -o a.ply").code, 2);
  EXPECT_EQ(run("extract field:sphere:16 -o a.ply --method nope").code, 2);
}

TEST_F(Cli, AFailedRunKeepsThePreviousOutput) {
  { std::ofstream(dir_ / "out.ply") << "previous"; }
  EXPECT_EQ(run("extract missing_8x8x8_uint8.raw --iso 1 -o out.ply").code, 1);
  EXPECT_EQ(slurp(dir_ / "out.ply"), "previous");
  EXPECT_EQ(stray_files({"out.ply"}), std::vector<std::string>{});
}

TEST_F(Cli, InfoDescribesTheVolume) {
  const Result r = run("info field:marschner-lobb:21 --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["dims"], nlohmann::json::array({21, 21, 21}));
  EXPECT_EQ(j["type"], "float32");
  EXPECT_EQ(j["default_iso"], 0.5);
  std::uint64_t total = 0;
  for (const auto& bin : j["histogram"]) total += bin["count"].get<std::uint64_t>();
  EXPECT_EQ(total, 21u * 21u * 21u);
  EXPECT_LT(j["min"].get<double>(), 0.5);
  EXPECT_GT(j["max"].get<double>(), 0.5);
}

// The 16 bins: where each of Otsu's bins holds one value (an 8-bit volume) they are its sums,
// without another pass; otherwise a pass counts them (16-bit values above 256 share bins). Both
// must be what counting every sample gives: floor((v - min) / ((max - min) / 16)), the top value
// in the last bin.
TEST_F(Cli, InfoBinsCountEverySample) {
  const auto check = [&](auto type, const std::string& name, int span, int offset) {
    using T = decltype(type);
    std::vector<T> v(37 * 29 * 23);
    std::uint64_t state = 7;
    for (T& x : v) {
      state = state * 6364136223846793005u + 1442695040888963407u;
      x = static_cast<T>(static_cast<int>((state >> 40) % static_cast<std::uint64_t>(span)) +
                         offset);
    }
    {
      std::ofstream f(dir_ / name, std::ios::binary);
      f.write(reinterpret_cast<const char*>(v.data()),
              static_cast<std::streamsize>(v.size() * sizeof(v[0])));
    }
    const auto [mn, mx] = std::minmax_element(v.begin(), v.end());
    const double lo = *mn, width = (static_cast<double>(*mx) - lo) / 16;
    std::vector<std::uint64_t> expected(16, 0);
    for (const T x : v)
      ++expected[static_cast<std::size_t>(std::clamp(static_cast<int>((x - lo) / width), 0, 15))];
    const Result r = run("info " + name + " --json");
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    std::vector<std::uint64_t> got;
    for (const auto& bin : j["histogram"]) got.push_back(bin["count"].get<std::uint64_t>());
    EXPECT_EQ(got, expected) << name;
  };
  check(std::uint8_t{}, "r_37x29x23_uint8.raw", 251, 3);
  check(std::int16_t{}, "r_37x29x23_int16.raw", 5003, -1700);
}

TEST_F(Cli, QualityMeasuresAWrittenMesh) {
  ASSERT_EQ(run("extract field:torus:32 -q -o t.ply").code, 0);
  const Result r = run("quality t.ply --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["euler"], 0);
  EXPECT_EQ(j["closed"], true);
  EXPECT_EQ(j["components"], 1);
  EXPECT_GT(j["radius_ratio_min"].get<double>(), 0.0);
  // A file carries no volume box: whether its boundary is the volume's border cannot be told.
  EXPECT_TRUE(j["watertight"].is_null());
  const Result text = run("quality t.ply");
  ASSERT_EQ(text.code, 0) << text.err;
  EXPECT_NE(text.out.find("watertight            cannot tell"), std::string::npos) << text.out;
  // Nor which boundary edges lie on it (it said 0 for an open gyroid's 1,000-odd).
  ASSERT_EQ(run("extract field:gyroid:32 -q -o g.ply").code, 0);
  const auto g = nlohmann::json::parse(run("quality g.ply --json").out);
  EXPECT_GT(g["boundary_edges"].get<int>(), 100);
  EXPECT_TRUE(g["border_boundary_edges"].is_null()) << g["border_boundary_edges"];
}

// The watertight key means the same for every method: an open gyroid leaves the volume, and only
// there has boundary edges, whether MC's vertices lie on the border planes or DC's in the border
// cells (both vertex variants).
TEST_F(Cli, WatertightMeansTheSameForEveryMethod) {
  for (const char* method : {"mc", "macet", "dc"}) {
    const Result r =
        run(std::string("extract field:gyroid:40 -q -o g.ply --stats - --method ") + method);
    ASSERT_EQ(r.code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_GT(j["boundary_edges"].get<int>(), 100) << method;
    EXPECT_EQ(j["border_boundary_edges"], j["boundary_edges"]) << method;
    EXPECT_EQ(j["watertight"], true) << method;
    EXPECT_EQ(j["nonmanifold_edges"], 0) << method;
  }
  const Result cell =
      run("extract field:gyroid:40 -q -o g.ply --stats - --method dc "
          "--dc-vertices cell");
  ASSERT_EQ(cell.code, 0) << cell.err;
  EXPECT_EQ(nlohmann::json::parse(cell.out)["watertight"], true);
  const Result bad = run("extract field:gyroid:40 -q -o g.ply --method dc --dc-vertices one");
  EXPECT_NE(bad.code, 0);
  EXPECT_NE(bad.err.find("--dc-vertices"), std::string::npos) << bad.err;
}

TEST_F(Cli, DemoRunsWithoutArguments) {
  const Result r = run("demo");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "isotile-demo.ply"));
  EXPECT_GT(nlohmann::json::parse(r.out)["triangles"].get<int>(), 10000);
  EXPECT_NE(r.err.find("isotile-demo.ply"), std::string::npos);
}

}  // namespace

namespace {

// --memory: bricked and streamed, the same bytes as an in-core run, at any thread count.
TEST_F(Cli, MemoryBudgetStreamsTheSameFile) {
  ASSERT_EQ(run("extract field:torus:48 -o whole.ply --normals -q").code, 0);
  for (const char* threads : {"1", "3"}) {
    const Result r = run(std::string("--threads ") + threads +
                         " extract field:torus:48 -o part.ply --normals --memory 60KiB "
                         "--stats s.json");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("bricks"), std::string::npos) << "no progress by bricks: " << r.err;
    EXPECT_EQ(slurp(dir_ / "part.ply"), slurp(dir_ / "whole.ply")) << threads << " threads";
    const auto j = nlohmann::json::parse(slurp(dir_ / "s.json"));
    EXPECT_GT(j["bricks"].get<int>(), 8);
    // A streamed run never holds every edge's faces: the topology keys of an in-core run, null.
    for (const char* key :
         {"boundary_edges", "border_boundary_edges", "nonmanifold_edges", "nonmanifold_vertices",
          "inconsistently_oriented_edges", "euler", "components", "closed", "watertight"})
      EXPECT_TRUE(j.contains(key) && j[key].is_null()) << key;
    for (const char* key : {"triangles", "vertices", "radius_ratio_min", "radius_ratio_mean",
                            "radius_ratio_q001", "radius_ratio_q01", "brick_cells", "peak_rss_mb"})
      EXPECT_TRUE(j.contains(key)) << key;
  }
}

TEST_F(Cli, BadMemoryBudgetsAreOneLineErrors) {
  for (const char* args :
       {"--memory 12XB -o a.ply", "--memory 100B -o a.ply", "--memory 1MiB -o a.obj",
        "--memory 1MiB --ascii -o a.ply", "--memory 1MiB --check-intersections -o a.ply"}) {
    const Result r = run(std::string("extract field:sphere:32 ") + args);
    EXPECT_EQ(r.code, 1) << args;
    EXPECT_EQ(count_of(r.err, "isotile: error:"), 1) << args << ": " << r.err;
    EXPECT_EQ(last_line(r.err).rfind("isotile: error:", 0), 0u) << args << ": " << r.err;
    EXPECT_TRUE(stray_files().empty()) << args;
  }
}

}  // namespace

namespace {

// Starts a long bricked run in the work folder and returns once its second pass (the one that
// writes the mesh) has begun; -1 where it never did.
pid_t start_bricked_run_and_wait_for_its_writing(const fs::path& dir) {
  const pid_t pid = ::fork();
  if (pid < 0) return -1;
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(127);
    std::freopen("err.txt", "w", stderr);
    ::execl(ISOTILE_CLI, ISOTILE_CLI, "extract", "field:gyroid:400", "--memory", "1MiB", "-o",
            "g.ply", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // The extract pass's progress lines ("isotile: extract: 2/N bricks") follow the count's.
  for (int i = 0; i < 600; ++i) {
    ::usleep(50000);
    if (slurp(dir / "err.txt").find("isotile: extract: ") != std::string::npos) return pid;
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, nullptr, 0);
  return -1;
}

// Ctrl-C in the middle of a long bricked run leaves neither the output nor a temporary behind.
TEST_F(Cli, InterruptedBrickedRunLeavesNoFiles) {
  const pid_t pid = start_bricked_run_and_wait_for_its_writing(dir_);
  ASSERT_GT(pid, 0) << "the extract pass never began: " << slurp(dir_ / "err.txt");
  ::kill(pid, SIGINT);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  // Ctrl-C cancels through the library's Progress: "isotile: cancelled", exit status 130.
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 130) << "the run was not cancelled";
  EXPECT_NE(slurp(dir_ / "err.txt").find("isotile: cancelled\n"), std::string::npos);
  EXPECT_EQ(stray_files({"err.txt"}), std::vector<std::string>{});
}

// A run killed outright (SIGKILL: the OOM killer, a batch system's hard limit), which no handler
// sees, leaves nothing either: the mesh is written to a file without a name until it is complete.
// Before, a hidden ".g.ply.tmp-PID-N.ply" of the mesh's size stayed beside the output.
TEST_F(Cli, AKilledBrickedRunLeavesNoFiles) {
  if (const int fd = ::open(dir_.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0600); fd >= 0)
    ::close(fd);
  else
    GTEST_SKIP() << dir_ << " cannot hold files without a name (no O_TMPFILE): a killed run "
                 << "leaves its named temporary there";
  const pid_t pid = start_bricked_run_and_wait_for_its_writing(dir_);
  ASSERT_GT(pid, 0) << "the extract pass never began: " << slurp(dir_ / "err.txt");
  ::kill(pid, SIGKILL);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  EXPECT_EQ(stray_files({"err.txt"}), std::vector<std::string>{});
}

}  // namespace
