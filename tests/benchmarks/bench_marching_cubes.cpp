// CPU Marching Cubes against VTK's vtkFlyingEdges3D, side by side in one run.
//
//   ./setup.sh --bench && build/tests/benchmarks/bench_marching_cubes [--threads N]
//
// Both run with the same number of threads (default 2) on the same in-memory samples; both produce
// an indexed mesh with shared vertices and no normals. After Google Benchmark's table, prints the
// ratio isotile / VTK of the median wall time per volume. Volumes from ../shared/data are skipped,
// with a message, when that folder is absent.
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/extract/marching_cubes.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"

#ifdef ISOTILE_HAVE_VTK
#include "vtk_peer.h"
#endif

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

}  // namespace

int main(int argc, char** argv) {
  int threads = 2;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
      continue;
    }
    args.push_back(argv[i]);
  }
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
#ifdef ISOTILE_HAVE_VTK
  bench::VtkFlyingEdges::set_threads(threads);
  std::printf("threads: %d (isotile TBB, VTK SMP backend %s)\n", threads,
              bench::VtkFlyingEdges::backend());
#else
  std::printf("threads: %d; VTK not found, isotile only\n", threads);
#endif

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
  cases.push_back(
      {"gyroid256", std::make_shared<Volume>(make_field_volume({FieldKind::Gyroid, 256})), 0.0});

  // The two must make the same surface: triangle counts compared exactly, once per volume, before
  // any timing (a mismatch fails the run).
  int mismatches = 0;
  std::printf("triangles (isotile / VTK):\n");
  for (const Case& c : cases) {
    const std::size_t ours = marching_cubes(c.volume->view(), {.iso = c.iso}).triangles.size();
#ifdef ISOTILE_HAVE_VTK
    const std::size_t theirs = bench::VtkFlyingEdges(c.volume->view()).run(c.iso);
    std::printf("  %-10s %zu / %zu%s\n", c.name.c_str(), ours, theirs,
                ours == theirs ? "" : "  MISMATCH");
    mismatches += ours != theirs;
#else
    std::printf("  %-10s %zu / (no VTK)\n", c.name.c_str(), ours);
#endif
  }

  for (const Case& c : cases) {
    benchmark::RegisterBenchmark(("isotile_mc/" + c.name).c_str(),
                                 [c](benchmark::State& state) {
                                   std::size_t tris = 0;
                                   for (auto _ : state) {
                                     Mesh m = marching_cubes(c.volume->view(),
                                                             {.iso = c.iso, .normals = false});
                                     tris = m.triangles.size();
                                     benchmark::DoNotOptimize(m.positions.data());
                                   }
                                   state.counters["triangles"] = static_cast<double>(tris);
                                 })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->Repetitions(5)
        ->ReportAggregatesOnly(true);
#ifdef ISOTILE_HAVE_VTK
    auto peer = std::make_shared<bench::VtkFlyingEdges>(c.volume->view());
    benchmark::RegisterBenchmark(("vtk_flying_edges/" + c.name).c_str(),
                                 [c, peer](benchmark::State& state) {
                                   std::size_t tris = 0;
                                   for (auto _ : state) tris = peer->run(c.iso);
                                   state.counters["triangles"] = static_cast<double>(tris);
                                 })
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->Repetitions(5)
        ->ReportAggregatesOnly(true);
#endif
  }

  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();

  std::printf("\nratio isotile / VTK (median wall time, %d threads)\n", threads);
  for (const Case& c : cases) {
    const auto a = g_median_ms.find("isotile_mc/" + c.name);
    const auto b = g_median_ms.find("vtk_flying_edges/" + c.name);
    if (a != g_median_ms.end() && b != g_median_ms.end())
      std::printf("  %-10s %8.2f ms vs %8.2f ms  ratio %.2f\n", c.name.c_str(), a->second,
                  b->second, a->second / b->second);
  }
  if (mismatches) {
    std::fprintf(stderr, "bench_marching_cubes: %d volume(s) where the triangle counts differ\n",
                 mismatches);
    return 1;
  }
  return 0;
}
