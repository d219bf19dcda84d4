// Macet against Marching Cubes, side by side in one run: speed and triangle quality.
//
//   cmake -S . -B build -DISOTILE_BUILD_BENCHMARKS=ON && cmake --build build --target bench_macet
//   build/tests/benchmarks/bench_macet [--threads N] [--no-max] [--intersections] [--relax R]...
//
// Google Benchmark times marching_cubes and macet(Fast) with the same number of threads (default
// 2) on the same in-memory samples, five repetitions each, no normals; then prints the ratio of
// the median wall times. Afterwards one run of each method (MC, Macet Fast, Macet Max unless
// --no-max) is measured: triangles, radius ratio min / mean / 0.1% / 1% quantiles, the wall time
// of that single run, and with --intersections the self-intersecting triangle pairs. Volumes:
// bonsai and engine from ../shared/data at 49.5 (skipped with a message when absent). Each
// --relax R adds Fast and Max rows with MacetOptions::relax = R, after a line saying how many
// samples the relaxation moved and how far the crossings of the grid edges moved along their
// edges (mean over all crossings, and max; voxels): the accuracy it costs.
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/extract/macet.h"
#include "core/extract/macet_relax.h"
#include "core/extract/marching_cubes.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/self_intersections.h"
#include "core/volume/volume_io.h"

namespace {

using namespace isotile;

struct Case {
  std::string name;
  std::shared_ptr<Volume> volume;
  double iso;
};

std::map<std::string, double> g_median_ms;

class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs)
      if (r.aggregate_name == "median")
        g_median_ms[r.run_name.function_name] = r.GetAdjustedRealTime();
    ConsoleReporter::ReportRuns(runs);
  }
};

template <class F>
Mesh timed(F&& f, double& ms) {
  const auto t0 = std::chrono::steady_clock::now();
  Mesh m = f();
  ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2;
  bool run_max = true, intersections = false;
  std::vector<double> relaxes;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
      continue;
    }
    if (std::strcmp(argv[i], "--no-max") == 0) {
      run_max = false;
      continue;
    }
    if (std::strcmp(argv[i], "--relax") == 0 && i + 1 < argc) {
      relaxes.push_back(std::atof(argv[++i]));
      continue;
    }
    if (std::strcmp(argv[i], "--intersections") == 0) {
      intersections = true;
      continue;
    }
    args.push_back(argv[i]);
  }
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  std::printf("threads: %d\n", threads);

  std::vector<Case> cases;
  const std::filesystem::path shared(ISOTILE_SHARED_DATA);
  for (auto [file, name] : {std::pair{"bonsai_256x256x256_uint8.raw.gz", "bonsai"},
                            std::pair{"engine_256x256x128_uint8.raw.gz", "engine"}}) {
    if (std::filesystem::exists(shared / file))
      cases.push_back(
          {name, std::make_shared<Volume>(read_volume((shared / file).string())), 49.5});
    else
      std::printf("skipping %s: %s not found\n", name, (shared / file).c_str());
  }

  for (const Case& c : cases) {
    benchmark::RegisterBenchmark(("mc/" + c.name).c_str(),
                                 [c](benchmark::State& state) {
                                   for (auto _ : state) {
                                     Mesh m = marching_cubes(c.volume->view(), {.iso = c.iso});
                                     benchmark::DoNotOptimize(m.positions.data());
                                   }
                                 })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->Repetitions(5)
        ->ReportAggregatesOnly(true);
    benchmark::RegisterBenchmark(("macet_fast/" + c.name).c_str(),
                                 [c](benchmark::State& state) {
                                   for (auto _ : state) {
                                     Mesh m = macet(c.volume->view(), {.iso = c.iso});
                                     benchmark::DoNotOptimize(m.positions.data());
                                   }
                                 })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->Repetitions(5)
        ->ReportAggregatesOnly(true);
  }

  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();

  std::printf("\nratio macet fast / mc (median wall time, %d threads)\n", threads);
  for (const Case& c : cases) {
    const auto a = g_median_ms.find("macet_fast/" + c.name);
    const auto b = g_median_ms.find("mc/" + c.name);
    if (a != g_median_ms.end() && b != g_median_ms.end())
      std::printf("  %-8s %8.2f ms vs %8.2f ms  ratio %.2f\n", c.name.c_str(), a->second, b->second,
                  a->second / b->second);
  }

  std::printf("\n%-8s %-11s %9s %10s %7s %9s %8s %9s%s\n", "volume", "method", "triangles", "min",
              "mean", "q0.1%", "q1%", "ms (1x)", intersections ? "  self-intersecting pairs" : "");
  for (const Case& c : cases) {
    const VolumeView view = c.volume->view();
    for (double relax : relaxes) {
      const auto r = detail::relax_pinned_samples(view, c.iso, relax);
      const Index3& n = view.dims;
      std::uint64_t moved = 0, crossings = 0;
      double sum = 0, most = 0;
      for (std::int64_t k = 0; k < n[2]; ++k)
        for (std::int64_t j = 0; j < n[1]; ++j)
          for (std::int64_t i = 0; i < n[0]; ++i) {
            const std::int64_t s = i + n[0] * (j + n[1] * k);
            const double f0 = view.value(i, j, k) - c.iso, g0 = r[s] - c.iso;
            moved += g0 != f0;
            const std::int64_t p[3] = {i, j, k}, stride[3] = {1, n[0], n[0] * n[1]};
            for (int a = 0; a < 3; ++a) {
              if (p[a] + 1 >= n[a]) continue;
              std::int64_t q[3] = {i, j, k};
              ++q[a];
              const double f1 = view.value(q[0], q[1], q[2]) - c.iso, g1 = r[s + stride[a]] - c.iso;
              if ((f0 >= 0) == (f1 >= 0)) continue;
              const double d = std::abs(g0 / (g0 - g1) - f0 / (f0 - f1));
              ++crossings;
              sum += d;
              most = std::max(most, d);
            }
          }
      std::printf(
          "%-8s relax %.2f moves %llu samples; crossings move %.4f on average, %.3f at most\n",
          c.name.c_str(), relax, static_cast<unsigned long long>(moved),
          sum / static_cast<double>(crossings), most);
    }
    struct Row {
      std::string name;
      std::function<Mesh()> run;
    };
    std::vector<Row> rows = {
        {"mc", [&] { return marching_cubes(view, {.iso = c.iso}); }},
        {"macet-fast", [&] { return macet(view, {.iso = c.iso}); }},
    };
    if (run_max)
      rows.push_back(
          {"macet-max", [&] { return macet(view, {.iso = c.iso, .quality = MacetQuality::Max}); }});
    for (double relax : relaxes) {
      const std::string tag = " r" + std::to_string(relax).substr(0, 4);
      rows.push_back({"macet-fast" + tag,
                      [&c, view, relax] { return macet(view, {.iso = c.iso, .relax = relax}); }});
      if (run_max)
        rows.push_back({"macet-max" + tag, [&c, view, relax] {
                          return macet(
                              view, {.iso = c.iso, .quality = MacetQuality::Max, .relax = relax});
                        }});
    }
    for (const Row& r : rows) {
      double ms = 0;
      const Mesh m = timed(r.run, ms);
      const QualityStats q = triangle_quality(m);
      std::printf("%-8s %-11s %9llu %10.3g %7.4f %9.4f %8.4f %9.1f", c.name.c_str(), r.name.c_str(),
                  static_cast<unsigned long long>(q.triangles), q.min, q.mean, q.q001, q.q01, ms);
      if (intersections)
        std::printf("  %llu", static_cast<unsigned long long>(self_intersections(m).pairs));
      std::printf("\n");
      std::fflush(stdout);
    }
  }
  return 0;
}
