// The memory budget, measured: `isotile extract --memory B` keeps the process's peak RSS (its
// stats' peak_rss_mb, the kernel's high-water mark) within B above the baseline of the same
// command on a tiny input, for every method, over bricks of a field and over the slabs of a
// gzip'd file (whose kept planes count too). Release builds only: sanitizers inflate memory.
#include <gtest/gtest.h>
#include <sys/personality.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_support.h"

namespace {

using Result = isotile::testing::CliResult;

// The gzip'd test volume the cases read in slabs.
class CliWaves : public isotile::testing::CliTest {
 protected:
  // An n^3 uint8 volume of smooth waves, gzip'd: only read front to back, so in slabs.
  std::string write_waves(int n) {
    std::vector<std::uint8_t> v(static_cast<std::size_t>(n) * n * n);
    for (int z = 0; z < n; ++z)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const double s = std::sin(0.2 * x) * std::cos(0.2 * y) +
                           std::sin(0.2 * y) * std::cos(0.2 * z) +
                           std::sin(0.2 * z) * std::cos(0.2 * x);
          v[(static_cast<std::size_t>(z) * n + y) * n + x] =
              static_cast<std::uint8_t>(std::lround(128 + 80 * s));
        }
    const std::string name = "waves_" + std::to_string(n) + "x" + std::to_string(n) + "x" +
                             std::to_string(n) + "_uint8.raw.gz";
    gzFile g = gzopen((dir_ / name).c_str(), "wb");
    gzwrite(g, v.data(), static_cast<unsigned>(v.size()));
    gzclose(g);
    return name;
  }
};

class CliMemory : public CliWaves {
 protected:
  void SetUp() override {
#ifdef ISOTILE_SANITIZED
    GTEST_SKIP() << "sanitizer builds inflate memory; the budget is measured in the Release pass";
#endif
    CliWaves::SetUp();
    // Inherited by the commands this process starts (see the allowance below).
    persona_ = ::personality(0xffffffff);
    aslr_off_ = persona_ != -1 && ::personality(persona_ | ADDR_NO_RANDOMIZE) != -1;
  }
  void TearDown() override {
    if (persona_ != -1) ::personality(persona_);
    CliWaves::TearDown();
  }
  int persona_ = -1;
  bool aslr_off_ = false;

  // Peak RSS in MiB of `isotile extract ARGS --stats -`, which makes at least `min_triangles`.
  double peak(const std::string& args, double min_triangles = 10000) {
    const Result r = run("extract " + args + " -q --stats -");
    EXPECT_EQ(r.code, 0) << args << "\n" << r.err;
    if (r.code != 0) return INFINITY;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_GE(j["triangles"].get<double>(), min_triangles) << args;
    return j["peak_rss_mb"].get<double>();
  }
};

// Each case's baseline is the same command on a tiny input of the same kind: the process then maps
// and touches the same code (the tiler, zlib, the extractor, and the libraries linked for other
// formats), so what the case adds above it is its working set, which the budget bounds.
TEST_F(CliMemory, PeakRssStaysWithinTheBudgetAboveTheBaseline) {
  struct Case {
    std::string args, tiny;  // the run and its baseline, both followed by the same options
    std::string options;
    double budget_mib;
    std::string format = "ply";
  };
  const std::string waves = write_waves(128), tiny_waves = write_waves(12);
  const Case cases[] = {
      // Float samples (32 MB in all) in bricks.
      {"field:gyroid:200", "field:gyroid:12", " --method mc --memory 8MiB", 8},
      {"field:gyroid:200", "field:gyroid:12", " --method macet --memory 8MiB", 8},
      {"field:gyroid:200", "field:gyroid:12", " --method dc --memory 8MiB", 8},
      // STL's records, 50 bytes a triangle. (Counted as PLY's 16 before, they overflowed
      // 256 MiB with two bricks in flight on a 2 GiB volume, beyond what a test here runs; DC
      // to STL at 8 MiB peaks 9.75 MiB above its baseline, with or without them: not here.)
      {"field:gyroid:200", "field:gyroid:12", " --method mc --memory 8MiB", 8, "stl"},
      // Simplified brick by brick, then in seam cells: the simplifier's bytes per face, with
      // each z-slice planned from the faces it holds (17.5 MiB above the baseline before, with
      // ASLR off: 450 and 800 bytes a face were too few).
      {"field:gyroid:256", "field:gyroid:12", " --method mc --simplify 0.25 --memory 16MiB", 16},
      // Macet max's halo (138 samples: the whole volume) and its state. The count pass reads the
      // whole volume too: 10.06-10.31 MiB above the baseline while the output's stdio buffer sat
      // on that read's freed pages (docs/tiler.md), 7.9-8.2 since.
      {"field:gyroid:80", "field:gyroid:12", " --method macet --quality max --memory 10MiB", 10},
      // Slabs of a gzip'd file, with the planes kept between slabs and zlib's buffers. The
      // surface is dense (630k triangles): Macet's crossings, counted per crossing once the
      // slabs are counted, cut them into thinner slices (before, Macet peaked 0.06-0.25 MiB
      // over 4 MiB here; with ASLR off, 6 runs).
      {waves, tiny_waves, " --iso 128.5 --method mc --memory 4MiB", 4},
      {waves, tiny_waves, " --iso 128.5 --method macet --memory 4MiB", 4},
      {waves, tiny_waves, " --iso 128.5 --method dc --memory 4MiB", 4},
  };
  // With ASLR on, one command's peak varies from run to run by up to 0.9 MiB (DC over the gzip'd
  // slabs at 4 MiB: 3.27 to 4.13 MiB above its baseline over 31 runs): the libraries' pages that
  // the kernel maps around each page fault (64 KiB windows of the virtual addresses) depend on
  // where each library was loaded, so the file-backed part of the RSS moved (9.42 to 9.77 MB at
  // exit over 6 runs of the tiny DC command) while the anonymous part stayed within 4 KiB. The
  // children run with ADDR_NO_RANDOMIZE where the kernel allows it (SetUp). What is left is
  // whether the second thread takes part in a step: DC at 4 MiB peaked 3.625 MiB above its
  // baseline in 19 of 20 runs and 4.0 in one (the other cases at least 0.25 MiB under their
  // budgets, 8 runs each), so 0.25 MiB above the budget is allowed; where ASLR cannot be turned
  // off, 0.5 MiB.
  const double allowance_mib = aslr_off_ ? 0.25 : 0.5;
  for (const Case& c : cases) {
    const double baseline = peak(c.tiny + c.options + " -o tiny." + c.format, 1);
    const double p = peak(c.args + c.options + " -o out." + c.format);
    EXPECT_LE(p, baseline + c.budget_mib + allowance_mib)
        << c.args << c.options << " " << c.format << ": peak " << p << " MiB, baseline " << baseline
        << " MiB, ASLR " << (aslr_off_ ? "off" : "on");
  }
}

// A budget that even one-cell slices of the surface overflow: the run says so on stderr, under
// --quiet too, before extracting, and still writes the exact mesh (no peak is measured: this one
// runs in the sanitizer pass too).
using CliBudget = CliWaves;
TEST_F(CliBudget, ASurfaceThatOverflowsTheBudgetIsSaidOnce) {
  const std::string waves = write_waves(128);
  const Result over =
      run("extract " + waves + " --iso 128.5 --method macet --memory 2MiB -q -o over.ply");
  ASSERT_EQ(over.code, 0) << over.err;
  EXPECT_EQ(over.err.find("isotile: warning: the memory budget of 2097152 bytes is too small for "
                          "this surface"),
            0u)
      << over.err;
  EXPECT_EQ(std::count(over.err.begin(), over.err.end(), '\n'), 1) << over.err;
  const Result whole = run("extract " + waves + " --iso 128.5 --method macet -q -o whole.ply");
  ASSERT_EQ(whole.code, 0) << whole.err;
  EXPECT_EQ(isotile::testing::slurp(dir_ / "over.ply"),
            isotile::testing::slurp(dir_ / "whole.ply"));
  const Result within =
      run("extract " + waves + " --iso 128.5 --method macet --memory 4MiB -q -o within.ply");
  EXPECT_EQ(within.code, 0);
  EXPECT_EQ(within.err, "");
}

// The tiler's tables of counts (16 bytes per sample row per brick column, held whole, outside the
// budget): where the cubes' would take more than a quarter of the budget, bricks span whole rows
// (one column); where even those take more, the run says so. On 2048 x 2048 x 512 at 16 MiB the
// cubes' tables (17 columns, 285 MB) peaked at 299 MiB without a word; whole rows: 43 MiB.
TEST_F(CliBudget, TablesBeyondTheBudgetAreSaid) {
  const Result small = run("extract field:sphere:128 --memory 256KiB -q -o small.ply --stats -");
  ASSERT_EQ(small.code, 0) << small.err;
  const auto stats = nlohmann::json::parse(small.out);
  EXPECT_EQ(stats["brick_grid"][0].get<std::int64_t>(), 1);
  EXPECT_EQ(stats["brick_cells"][0].get<std::int64_t>(), 127);
  EXPECT_EQ(small.err,
            "isotile: warning: the memory budget of 262144 bytes leaves out the tiler's tables of "
            "counts, 262144 bytes for this plan (16 per sample row per brick column: 16384 rows, 1 "
            "column); the run goes over the budget\n");
  EXPECT_EQ(run("extract field:sphere:128 --memory 64MiB -q -o large.ply").err, "");
  // Where the cubes' tables fit, cubes stay (they read the least halo).
  const Result cubes = run("extract field:sphere:128 --memory 4MiB -q -o cubes.ply --stats -");
  ASSERT_EQ(cubes.code, 0) << cubes.err;
  EXPECT_EQ(cubes.err, "");
  EXPECT_GT(nlohmann::json::parse(cubes.out)["brick_grid"][0].get<std::int64_t>(), 1);
  EXPECT_EQ(isotile::testing::slurp(dir_ / "small.ply"),
            isotile::testing::slurp(dir_ / "large.ply"));
  EXPECT_EQ(isotile::testing::slurp(dir_ / "cubes.ply"),
            isotile::testing::slurp(dir_ / "large.ply"));
}

// A budget above what the process can have is taken (a small volume plans far less) but said,
// once, under --quiet too; the summary line counts one brick as one.
TEST_F(CliBudget, ABudgetAboveTheMachinesMemoryIsSaid) {
  const Result big = run("extract field:sphere:16 --memory 1000TiB -o big.ply");
  ASSERT_EQ(big.code, 0) << big.err;
  EXPECT_NE(big.err.find("isotile: warning: --memory 1000TiB is more than the "), std::string::npos)
      << big.err;
  EXPECT_NE(big.err.find(" vertices in 1 brick of 15x15x15 cells\n"), std::string::npos) << big.err;
  const Result quiet = run("extract field:sphere:16 --memory 1000TiB -q -o quiet.ply");
  ASSERT_EQ(quiet.code, 0) << quiet.err;
  EXPECT_EQ(quiet.err.rfind("isotile: warning: --memory 1000TiB is more than the ", 0), 0u)
      << quiet.err;
  EXPECT_EQ(std::count(quiet.err.begin(), quiet.err.end(), '\n'), 1) << quiet.err;
  EXPECT_EQ(run("extract field:sphere:16 --memory 1MiB -q -o small.ply").err, "");
}

}  // namespace
