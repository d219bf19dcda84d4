// Distributed extraction (tiler/mpi_extract.h): `mpirun -np K isotile extract --memory` on this
// machine must write the very bytes the single-process run writes, for every method, every rank
// count from 1 to 4 and each input kind ranks read in parallel; a failing rank must leave no file.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_support.h"
#ifdef ISOTILE_HAVE_MPI
#include "tiler/mpi_extract.h"
#endif

namespace {

using isotile::testing::CliResult;
using isotile::testing::slurp;
namespace fs = std::filesystem;
using json = nlohmann::json;

class MpiCli : public isotile::testing::CliTest {
 protected:
  void SetUp() override {
    CliTest::SetUp();
    // The GL program cache and Mesa's shader cache of the ranks (GlBackendRunsOnEveryRank) beside
    // the work directory (whose files the tests count), not in the home folder: ctest's
    // ENVIRONMENT for these tests holds LSAN_OPTIONS.
    cache_ = dir_.string() + "-xdg";
    setenv("XDG_CACHE_HOME", cache_.c_str(), 1);
#ifndef ISOTILE_MPIRUN
    ISOTILE_SKIP(Mpi, "isotile was built without MPI (libopenmpi-dev, ISOTILE_MPI)");
#else
    if (!fs::exists(ISOTILE_MPIRUN)) ISOTILE_SKIP(Mpi, "no mpirun at " << ISOTILE_MPIRUN);
#endif
  }

  void TearDown() override {
    fs::remove_all(cache_);
    CliTest::TearDown();
  }
  fs::path cache_;

  // `isotile extract ARGS` on `ranks` ranks; `env` is passed to every rank. Shared memory between
  // the ranks of this one machine (ob1 and vader): without them OpenMPI first probes UCX, which
  // adds about 0.2 s to each launch here.
  CliResult run_mpi(int ranks, const std::string& args, const std::string& env = "") {
#ifdef ISOTILE_MPIRUN
    std::string launcher =
        std::string("'") + ISOTILE_MPIRUN +
        "' --allow-run-as-root --oversubscribe --mca pml ob1 --mca btl self,vader -np " +
        std::to_string(ranks);
    if (!env.empty()) launcher = env + " " + launcher + " -x " + env.substr(0, env.find('='));
    return run("-q extract " + args, launcher);
#else
    (void)ranks, (void)args, (void)env;
    return {};
#endif
  }

  // The single-process file and stats, then the same run on each rank count: same bytes, same
  // whole-mesh statistics, and the ranks' own counts adding up to the whole.
  void expect_same_as_single_process(const std::string& input, const std::string& options,
                                     const std::vector<int>& rank_counts,
                                     const std::string& ext = "ply") {
    for (const std::string& name : stray_files({"v.raw", "v.nhdr"})) fs::remove(dir_ / name);
    const std::string single = "single." + ext;
    const CliResult s =
        run("-q extract " + input + " " + options + " -o " + single + " --stats single.json");
    ASSERT_EQ(s.code, 0) << s.err;
    const std::string expected = slurp(dir_ / single);
    const json js = json::parse(slurp(dir_ / "single.json"));
    // Several bricks, or the ranks would have nothing to share.
    ASSERT_GE(js["bricks"].get<int>(), 4) << options;
    ASSERT_GT(js["triangles"].get<std::uint64_t>(), 1000u);
    for (int k : rank_counts) {
      const std::string out = "mpi" + std::to_string(k) + "." + ext;
      const std::string stats = "mpi" + std::to_string(k) + ".json";
      const CliResult r = run_mpi(k, input + " " + options + " -o " + out + " --stats " + stats);
      ASSERT_EQ(r.code, 0) << k << " ranks: " << r.err;
      EXPECT_TRUE(slurp(dir_ / out) == expected) << options << " on " << k << " ranks";
      const json j = json::parse(slurp(dir_ / stats));
      for (const char* key :
           {"triangles", "vertices", "bricks", "radius_ratio_min", "radius_ratio_mean",
            "radius_ratio_median", "radius_ratio_q001", "degenerate_triangles"})
        EXPECT_EQ(j[key], js[key]) << key << " on " << k << " ranks";
      ASSERT_EQ(j["ranks"].get<int>(), k);
      ASSERT_EQ(j["per_rank"].size(), static_cast<std::size_t>(k));
      std::uint64_t triangles = 0;
      std::int64_t counted = 0, extracted = 0;
      for (const auto& rank : j["per_rank"]) {
        triangles += rank["triangles"].get<std::uint64_t>();
        counted += rank["bricks_counted"].get<std::int64_t>();
        extracted += rank["bricks_extracted"].get<std::int64_t>();
        // Every rank has bricks of its own in both passes (there are more bricks than ranks).
        EXPECT_GT(rank["bricks_counted"].get<std::int64_t>(), 0);
        EXPECT_GT(rank["bricks_extracted"].get<std::int64_t>(), 0);
      }
      EXPECT_EQ(triangles, j["triangles"].get<std::uint64_t>());
      EXPECT_EQ(counted, j["bricks"].get<std::int64_t>());
      // The ranks' extracted bricks are z-slices, as the whole run's bricks_extracted.
      EXPECT_EQ(extracted, j["bricks_extracted"].get<std::int64_t>());
      EXPECT_GE(j["load_imbalance"].get<double>(), 1.0);
      EXPECT_EQ(j["brick_seconds"]["extract"].size(), j["bricks"].get<std::size_t>());
      // The stages' busy seconds, summed over the ranks: the same stages, and the bricks took
      // time to extract and to write.
      ASSERT_TRUE(j["seconds"].contains("stages")) << k;
      for (const auto& stage : js["seconds"]["stages"].items())
        EXPECT_GE(j["seconds"]["stages"].value(stage.key(), -1.0), 0.0) << stage.key();
      EXPECT_GT(j["seconds"]["stages"]["extract"].get<double>(), 0.0) << k;
      EXPECT_GT(j["seconds"]["stages"]["write"].get<double>(), 0.0) << k;
      // A GL backend's report adds up over the ranks as over one process's bricks: the same
      // bytes uploaded, the same stages, a cache state (null, as in one process, for the CPU).
      EXPECT_EQ(j["upload_bytes"], js["upload_bytes"]) << k << " ranks";
      EXPECT_EQ(j["gl_program_cache"].is_null(), js["gl_program_cache"].is_null()) << k;
      EXPECT_EQ(j["seconds"].contains("gl"), js["seconds"].contains("gl")) << k;
      if (js["seconds"].contains("gl")) {
        for (const auto& stage : js["seconds"]["gl"].items()) {
          ASSERT_TRUE(j["seconds"]["gl"].contains(stage.key())) << stage.key();
          EXPECT_GE(j["seconds"]["gl"][stage.key()].get<double>(), 0.0) << stage.key();
        }
        EXPECT_GT(j["upload_bytes"].get<std::uint64_t>(), 0u);
        const json& cache = j["gl_program_cache"];
        // Every rank loaded or compiled the programs its bricks needed.
        EXPECT_GE(cache["loaded"].get<int>() + cache["compiled"].get<int>(), k) << cache;
      }
    }
    EXPECT_EQ(stray_files({single, "single.json", "mpi1." + ext, "mpi2." + ext, "mpi3." + ext,
                           "mpi4." + ext, "mpi1.json", "mpi2.json", "mpi3.json", "mpi4.json",
                           "v.raw", "v.nhdr"}),
              std::vector<std::string>{});
  }

  // A raw uint16 volume, big-endian (the ranks swap their own bricks): a wavy surface.
  void write_raw(const fs::path& file, int n) {
    std::ofstream out(file, std::ios::binary);
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          const auto v = static_cast<std::uint16_t>(1000 + 37 * ((i * 7 + j * 3 + k * 5) % 23) +
                                                    20 * (i + j + k));
          const auto be = static_cast<std::uint16_t>((v >> 8) | (v << 8));
          out.write(reinterpret_cast<const char*>(&be), 2);
        }
  }
};

TEST_F(MpiCli, MarchingCubesMatchesSingleProcessOnOneToFourRanks) {
  expect_same_as_single_process("field:gyroid:40", "--method mc --normals --memory 96KiB",
                                {1, 2, 3, 4});
}

// Each rank's seconds are its own work, not its wait for the others: one brick on two ranks
// (rank 1 extracts nothing) is an imbalance of about 2 (it said 1.0000000131, every rank's
// seconds being the slowest's).
TEST_F(MpiCli, TheLoadImbalanceIsTheRanksOwnWork) {
  const CliResult r = run_mpi(2, "field:gyroid:64 --memory 64MiB -o o.ply --stats s.json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(slurp(dir_ / "s.json"));
  ASSERT_EQ(j["bricks"].get<int>(), 1);
  EXPECT_EQ(j["per_rank"][1]["bricks_extracted"].get<int>(), 0);
  EXPECT_GT(j["load_imbalance"].get<double>(), 1.5) << j["per_rank"];
}

TEST_F(MpiCli, IsoAutoFindsTheSingleProcessValueOnEveryRank) {
  expect_same_as_single_process("field:gyroid:48", "--iso auto --memory 256KiB", {2});
}

TEST_F(MpiCli, AnIsovalueWithNoSurfaceIsOneErrorNamingTheRange) {
  const CliResult r = run_mpi(2, "field:sphere:32 --iso 5 --memory 256KiB -o m.ply");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("isotile: error: no surface at iso 5: the samples range from "),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "m.ply"));
}

TEST_F(MpiCli, MacetMatchesSingleProcess) {
  expect_same_as_single_process("field:gyroid:40", "--method macet --memory 512KiB", {2, 3});
  expect_same_as_single_process("field:torus:40", "--method macet --quality max --memory 600KiB",
                                {4});
}

TEST_F(MpiCli, DualContouringMatchesSingleProcess) {
  expect_same_as_single_process("field:gyroid:40", "--method dc --memory 96KiB", {2, 4});
  // Binary STL (fixed-size records), and quads into PLY (polygons of four corners).
  expect_same_as_single_process("field:gyroid:40", "--method dc --memory 96KiB", {3}, "stl");
  expect_same_as_single_process("field:gyroid:40", "--method dc --quads --memory 96KiB", {3});
  // Quads into STL are refused on the ranks' path too (STL holds triangles only).
  const CliResult r = run_mpi(2, "field:gyroid:16 --method dc --quads --memory 64KiB -o q.stl");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("STL holds triangles only"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "q.stl"));
}

TEST_F(MpiCli, GlBackendRunsOnEveryRank) {
  // Each rank makes its own OpenGL context (llvmpipe here, one GPU per rank on a cluster).
#if defined(ISOTILE_SANITIZED) && !defined(__SANITIZE_THREAD__)
  // The MPI tests unwind every allocation slowly under ASan (fast_unwind_on_malloc=0,
  // tests/CMakeLists.txt); llvmpipe's JIT under that unwinder stalls (observed: no progress in 9
  // minutes). ThreadSanitizer unwinds fast and runs it.
  GTEST_SKIP() << "ASan builds: llvmpipe stalls under the slow unwinder the MPI tests need; "
                  "the Release pass runs this test";
#endif
  const CliResult probe = run("-q extract field:gyroid:40 --backend hp -o probe.ply");
  if (probe.code != 0) ISOTILE_SKIP(Gl, "no OpenGL context: " << probe.err);
  fs::remove(dir_ / "probe.ply");
  expect_same_as_single_process("field:gyroid:40", "--backend hp --memory 96KiB", {2});
}

TEST_F(MpiCli, RawAndNrrdInputsAreReadInPlaceByEachRank) {
  write_raw(dir_ / "v.raw", 36);
  expect_same_as_single_process("v.raw --dims 36,36,36 --type uint16 --endian big --iso 2000",
                                "--memory 96KiB", {3});
  std::ofstream(dir_ / "v.nhdr") << "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 36 36 36\n"
                                    "encoding: raw\nendian: big\ndata file: v.raw\n";
  expect_same_as_single_process("v.nhdr --iso 2000", "--method dc --memory 96KiB", {2});
}

TEST_F(MpiCli, AFailingRankEndsTheRunNamingItsBrickAndLeavesNoFile) {
  for (const char* pass : {"count", "extract"}) {
    const CliResult r = run_mpi(3, "field:gyroid:40 --memory 96KiB -o out.ply",
                                std::string("ISOTILE_MPI_TEST_FAIL=5:") + pass);
    EXPECT_NE(r.code, 0) << pass;
    EXPECT_NE(r.err.find("isotile: error: rank "), std::string::npos) << r.err;
    // The hook's brick 5 counts from 0, the message from 1.
    EXPECT_NE(r.err.find(", brick 6 of "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("injected failure"), std::string::npos) << r.err;
    // One error line, from rank 0, whichever rank failed.
    std::size_t lines = 0;
    for (std::size_t p = 0; (p = r.err.find("isotile: error:", p)) != std::string::npos; ++p)
      ++lines;
    EXPECT_EQ(lines, 1u) << r.err;
    EXPECT_EQ(stray_files(), std::vector<std::string>{}) << pass;
  }
}

TEST_F(MpiCli, ARankThatDiesLeavesNoFile) {
  // Brick 0 goes to some rank in the extract pass, rank 0 itself for some plans: the launcher
  // ends the job and the ranks it stops remove the temporary.
  for (const char* brick : {"0", "5"}) {
    const CliResult r = run_mpi(3, "field:gyroid:40 --memory 96KiB -o out.ply",
                                std::string("ISOTILE_MPI_TEST_FAIL=") + brick + ":kill");
    EXPECT_NE(r.code, 0);
    EXPECT_NE(r.err.find("signal 9"), std::string::npos) << r.err;
    EXPECT_EQ(stray_files(), std::vector<std::string>{}) << brick;
  }
}

TEST_F(MpiCli, GzipInputsAndOtherCommandsAreRefused) {
  const CliResult gz =
      run_mpi(2, std::string(ISOTILE_TEST_DATA) +
                     "/bucky_32x32x32_uint8.raw.gz --iso 100 --memory 64KiB -o out.ply");
  EXPECT_NE(gz.code, 0);
  EXPECT_NE(gz.err.find("gzip'd data can only be read front to back"), std::string::npos) << gz.err;
  // A NRRD's gzip data attached after its header too (it was read whole by every rank).
  std::ofstream(dir_ / "gz.nrrd", std::ios::binary)
      << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 32 32 32\nencoding: gzip\n\n"
      << slurp(fs::path(ISOTILE_TEST_DATA) / "bucky_32x32x32_uint8.raw.gz");
  const CliResult nrrd = run_mpi(2, "gz.nrrd --iso 100 --memory 256KiB -o out.ply");
  EXPECT_NE(nrrd.code, 0);
  EXPECT_NE(nrrd.err.find("gz.nrrd: gzip'd data can only be read front to back"), std::string::npos)
      << nrrd.err;
  const CliResult simplify = run_mpi(2, "field:gyroid:40 --memory 96KiB --simplify 0.5 -o out.ply");
  EXPECT_NE(simplify.code, 0);
  EXPECT_NE(simplify.err.find("--simplify is not distributed"), std::string::npos) << simplify.err;
  const CliResult in_core = run_mpi(2, "field:gyroid:40 -o out.ply");
  EXPECT_NE(in_core.code, 0);
  EXPECT_NE(in_core.err.find("only `extract --memory SIZE` runs distributed"), std::string::npos)
      << in_core.err;
  EXPECT_EQ(stray_files({"gz.nrrd"}), std::vector<std::string>{});
}

// Damaged inputs fail on every rank count as they do in one process: one line naming the file,
// no output. A raw file one plane short (read in place by each rank) and a NRRD whose raw data
// after a skipped line is cut off (a layout teem reads whole, so each rank reads it).
TEST_F(MpiCli, DamagedInputsAreRefusedAsInOneProcess) {
  write_raw(dir_ / "v.raw", 36);
  std::filesystem::resize_file(dir_ / "v.raw", 36 * 36 * 35 * 2);
  std::ofstream(dir_ / "cut.nrrd", std::ios::binary)
      << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 41 41 41\nencoding: raw\nline skip: 1\n\n"
      << "a skipped line\n"
      << std::string(41 * 41 * 20, '\x40');
  for (const auto& [input, what] :
       {std::pair<std::string, std::string>{"v.raw --dims 36,36,36 --type uint16 --iso 2000",
                                            "v.raw: file holds 90720 bytes but 36x36x36 uint16"},
        {"cut.nrrd --iso 60", "cut.nrrd: not a readable NRRD file"}}) {
    for (int ranks : {1, 3}) {
      const CliResult r = run_mpi(ranks, input + " --memory 96KiB -o out.ply");
      EXPECT_EQ(r.code, 1) << input << " on " << ranks << " ranks: " << r.err;
      EXPECT_NE(r.err.find(what), std::string::npos) << r.err;
      std::size_t lines = 0;
      for (std::size_t p = 0; (p = r.err.find("isotile: error:", p)) != std::string::npos; ++p)
        ++lines;
      EXPECT_EQ(lines, 1u) << r.err;
      EXPECT_EQ(stray_files({"v.raw", "cut.nrrd"}), std::vector<std::string>{}) << input;
    }
  }
}

TEST_F(MpiCli, ALauncherWhoseTasksMpiSeesAloneIsRefused) {
  // srun without a PMI plugin: every task would be a world of one writing the whole mesh.
  const CliResult r = run("-q extract field:gyroid:40 --memory 96KiB -o out.ply",
                          "SLURM_PROCID=0 SLURM_STEP_NUM_TASKS=2");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("the launcher started 2 tasks but MPI sees each alone"), std::string::npos)
      << r.err;
  EXPECT_EQ(stray_files(), std::vector<std::string>{});
}

#ifdef ISOTILE_HAVE_MPI
TEST(MpiBalance, CostliestBricksFirstToTheLeastLoadedRank) {
  // One brick holds half the surface: it gets a rank of its own, the rest share the other.
  const std::vector<int> owner = isotile::balance_bricks({1, 1, 10, 1, 1, 1, 1, 1, 1, 1, 1}, 2);
  double load[2] = {0, 0};
  const double cost[] = {1, 1, 10, 1, 1, 1, 1, 1, 1, 1, 1};
  for (std::size_t b = 0; b < owner.size(); ++b) load[owner[b]] += cost[b];
  EXPECT_EQ(load[0], 10);
  EXPECT_EQ(load[1], 10);
  // A contiguous split by position alone would give 13 and 7.
  // More ranks than bricks: each brick on a rank of its own.
  const std::vector<int> spread = isotile::balance_bricks({3, 2, 1}, 5);
  EXPECT_EQ(spread, (std::vector<int>{0, 1, 2}));
}

TEST(MpiBalance, CostGrowsWithCellsAndFaces) {
  const isotile::Box3 small{{0, 0, 0}, {10, 10, 10}}, large{{0, 0, 0}, {20, 20, 20}};
  EXPECT_LT(isotile::brick_cost(small, 0), isotile::brick_cost(large, 0));
  EXPECT_LT(isotile::brick_cost(small, 100), isotile::brick_cost(small, 200));
  EXPECT_GT(isotile::brick_cost(small, 0), 0);
}
#endif

}  // namespace
