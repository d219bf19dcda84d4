// VTK 9.1's vtkFlyingEdges3D as a one-shot user meets it: reads a volume (isotile's readers, the
// same samples `isotile extract` sees), copies it into a vtkImageData, then times Flying Edges'
// first call in this process (its first touch of its output arrays and its thread start-up
// included) and, for comparison, the median of three calls after it.
//
//   vtk_cold VOLUME ISO [THREADS]     (THREADS: default 2)
//
// Prints one line: `first_s S warm_s S triangles N backend B threads T first_cpu_s S`
// (first_cpu_s: the CPU seconds of all threads during the first call). Driven by
// tests/benchmarks/bench_cold.sh, which runs it in fresh processes.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include <sys/resource.h>

#include "core/volume/volume_io.h"
#include "vtk_peer.h"

int main(int argc, char** argv) {
  if (argc < 3 || argc > 4) {
    std::fprintf(stderr, "usage: vtk_cold VOLUME ISO [THREADS]\n");
    return 2;
  }
  try {
    const double iso = std::stod(argv[2]);
    const int threads = argc > 3 ? std::atoi(argv[3]) : 2;
    if (threads < 1) throw std::invalid_argument("THREADS must be at least 1");
    const isotile::Volume volume = isotile::read_volume(argv[1]);
    // The backend and thread count are settings, chosen before the clock as a VTK user would.
    isotile::bench::VtkFlyingEdges::set_threads(threads);
    isotile::bench::VtkFlyingEdges fe(volume.view());

    using Clock = std::chrono::steady_clock;
    auto timed = [&](std::size_t* triangles) {
      const auto t0 = Clock::now();
      *triangles = fe.run(iso);
      return std::chrono::duration<double>(Clock::now() - t0).count();
    };
    // CPU seconds of every thread of the process (user and system), which load on the machine
    // inflates less than wall time.
    auto cpu = [] {
      rusage u{};
      getrusage(RUSAGE_SELF, &u);
      return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
             1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
    };
    std::size_t triangles = 0, again = 0;
    const double cpu0 = cpu();
    const double first = timed(&triangles);
    const double first_cpu = cpu() - cpu0;
    double warm[3];
    for (double& w : warm) w = timed(&again);
    std::sort(warm, warm + 3);
    std::printf("first_s %.6f warm_s %.6f triangles %zu backend %s threads %d first_cpu_s %.6f\n",
                first, warm[1], triangles, isotile::bench::VtkFlyingEdges::backend(), threads,
                first_cpu);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "vtk_cold: %s\n", e.what());
    return 1;
  }
  return 0;
}
