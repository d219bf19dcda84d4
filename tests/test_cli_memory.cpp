// The memory budget, measured: `isotile extract --memory B` keeps the process's peak RSS (its
// stats' peak_rss_mb, the kernel's high-water mark) within B above the baseline of a process that
// extracts almost nothing, for every method, over bricks of a field and over the slabs of a
// gzip'd file (whose kept planes count too). Release builds only: sanitizers inflate memory.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cli_support.h"

namespace {

using Result = isotile::testing::CliResult;

class CliMemory : public isotile::testing::CliTest {
 protected:
  void SetUp() override {
#ifdef ISOTILE_SANITIZED
    GTEST_SKIP() << "sanitizer builds inflate memory; the budget is measured in the Release pass";
#endif
    CliTest::SetUp();
  }

  // Peak RSS in MiB of `isotile extract ARGS --stats -`.
  double peak(const std::string& args) {
    const Result r = run("extract " + args + " -q --stats -");
    EXPECT_EQ(r.code, 0) << args << "\n" << r.err;
    if (r.code != 0) return INFINITY;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_GT(j["triangles"].get<double>(), 10000) << args;
    return j["peak_rss_mb"].get<double>();
  }

  // A 128^3 uint8 volume of smooth waves, gzip'd: only read front to back, so in slabs.
  std::string write_waves() {
    const int n = 128;
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
    const std::string name = "waves_128x128x128_uint8.raw.gz";
    gzFile g = gzopen((dir_ / name).c_str(), "wb");
    gzwrite(g, v.data(), static_cast<unsigned>(v.size()));
    gzclose(g);
    return name;
  }
};

TEST_F(CliMemory, PeakRssStaysWithinTheBudgetAboveTheBaseline) {
  const double baseline = peak("field:sphere:48 -o tiny.ply");
  ASSERT_TRUE(std::isfinite(baseline));
  struct Case {
    std::string args;
    double budget_mib;
  };
  const std::string waves = write_waves();
  const Case cases[] = {
      // Float samples (32 MB in all) in bricks.
      {"field:gyroid:200 --method mc --memory 8MiB", 8},
      {"field:gyroid:200 --method macet --memory 8MiB", 8},
      {"field:gyroid:200 --method dc --memory 8MiB", 8},
      // Macet max's halo (138 samples: the whole volume) and its state.
      {"field:gyroid:80 --method macet --quality max --memory 10MiB", 10},
      // Slabs of a gzip'd file, with the planes kept between slabs and zlib's buffers.
      {waves + " --iso 128.5 --method mc --memory 2MiB", 2},
      {waves + " --iso 128.5 --method macet --memory 2MiB", 2},
      {waves + " --iso 128.5 --method dc --memory 2MiB", 2},
  };
  for (const Case& c : cases) {
    const double p = peak(c.args + " -o out.ply");
    EXPECT_LE(p, baseline + c.budget_mib)
        << c.args << ": peak " << p << " MiB, baseline " << baseline << " MiB";
  }
}

}  // namespace
