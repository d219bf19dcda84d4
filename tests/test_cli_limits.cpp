// Process limits that shared machines and batch systems set: a file-size limit (ulimit -f) and an
// address-space limit that leaves no room for a worker thread's stack (ulimit -v; a process limit,
// ulimit -u or a container's pids.max, fails the same call). Each ends in one error line and exit
// 1 with no temporary left and an existing output kept, or in a complete run: never a death by
// signal, an abort or a hang.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli_support.h"

namespace {

using isotile::testing::CliResult;
using isotile::testing::slurp;

class CliLimits : public isotile::testing::CliTest {
 protected:
  void write_old_output() { std::ofstream(dir_ / "out.ply") << "old\n"; }
};

// SIGXFSZ would kill the process with its temporary beside the output; ignored, the write fails
// with EFBIG and the writer reports it. In core, out of core (records placed with pwrite) and the
// --stats file.
TEST_F(CliLimits, AFileSizeLimitIsAnErrorAndKeepsTheOldOutput) {
  for (const std::string extra : {"", "--memory 1MiB"}) {
    write_old_output();
    const CliResult r = run("-q extract field:gyroid:64 -o out.ply " + extra, "ulimit -f 64 &&");
    EXPECT_EQ(r.code, 1) << extra << ": " << r.err;
    EXPECT_NE(r.err.find("isotile: error: cannot write out.ply: File too large"), std::string::npos)
        << extra << ": " << r.err;
    EXPECT_EQ(slurp(dir_ / "out.ply"), "old\n") << extra;
    EXPECT_EQ(stray_files({"out.ply"}), std::vector<std::string>{}) << extra;
  }
}

// Steps the address-space limit up from where the program loads at all: at the low end a worker
// thread's stack no longer fits (pthread_create fails), higher up the run completes. Before, the
// failure printed TBB's message and then waited in tbb::finalize for ever (or, with --threads 1,
// aborted after writing the mesh).
TEST_F(CliLimits, AWorkerThreadThatCannotStartIsAnErrorNotAHang) {
#ifdef ISOTILE_SANITIZED
  GTEST_SKIP() << "sanitizer runtimes reserve terabytes of address space: ulimit -v cannot apply";
#endif
  int worker_failures = 0, completed = 0;
  for (int kib = 16000; kib <= 96000 && completed < 4; kib += 2000) {
    const std::string limit = "ulimit -v " + std::to_string(kib) + " &&";
    if (run("--version", limit).code != 0) continue;  // the loader itself does not fit yet
    for (const std::string threads : {"", "--threads 1 "}) {
      const CliResult r = run("-q " + threads + "extract field:sphere:16 -o out.ply",
                              limit + " timeout -s KILL 60");
      const std::string where = std::to_string(kib) + " KiB " + threads;
      ASSERT_TRUE(r.code == 0 || r.code == 1)
          << where << ": exit " << r.code << " (137: a hang, killed; 134: an abort)\n"
          << r.err;
      if (r.code == 0) {
        ++completed;
        EXPECT_GT(std::filesystem::file_size(dir_ / "out.ply"), 1000u) << where;
        std::filesystem::remove(dir_ / "out.ply");
        continue;
      }
      EXPECT_EQ(r.err.rfind("isotile: error: ", 0), 0u) << where << ": " << r.err;
      EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << where << ": one line\n" << r.err;
      if (r.err.find("a worker thread could not be started") != std::string::npos)
        ++worker_failures;
      EXPECT_EQ(stray_files(), std::vector<std::string>{}) << where;
    }
  }
  EXPECT_GT(completed, 0) << "no limit up to 96000 KiB let the run complete";
  if (worker_failures == 0)
    GTEST_SKIP() << "no address-space limit here stopped a worker thread and nothing else";
}

// An in-core run whose samples cannot fit in what the process may have is refused before the
// read, naming the need, the limit and a --memory budget, and that budget then runs within the
// same limit and gives the in-core file. Before, under overcommit the OOM killer ended such a run
// part-way through the read (SIGKILL, no message); under ulimit -v the allocation failed after
// the header was read ("cannot allocate 512 MiB for a volume ...", with no way out named).
TEST_F(CliLimits, AVolumeThatCannotFitIsRefusedBeforeTheReadWithABudgetThatRuns) {
#ifdef ISOTILE_SANITIZED
  GTEST_SKIP() << "sanitizer runtimes reserve terabytes of address space: ulimit -v cannot apply";
#endif
  // 488 MiB of address space: less than the 512 MiB of samples of a 512^3 float32 field.
  const std::string limit = "ulimit -v 500000 &&";
  write_old_output();
  const CliResult refused = run("-q extract field:gyroid:512 --iso 0 -o out.ply", limit);
  EXPECT_EQ(refused.code, 1) << refused.err;
  EXPECT_EQ(refused.err.rfind("isotile: error: field:gyroid:512: in core, its samples alone take "
                              "512 MiB, more than the ",
                              0),
            0u)
      << refused.err;
  EXPECT_NE(refused.err.find("(left by ulimit -v)"), std::string::npos) << refused.err;
  EXPECT_EQ(refused.err.find('\n'), refused.err.size() - 1) << "one line\n" << refused.err;
  EXPECT_EQ(slurp(dir_ / "out.ply"), "old\n");
  EXPECT_EQ(stray_files({"out.ply"}), std::vector<std::string>{});

  const std::string marker = "within SIZE (e.g. ";
  const std::size_t at = refused.err.find(marker);
  ASSERT_NE(at, std::string::npos) << refused.err;
  const std::string budget =
      refused.err.substr(at + marker.size(), refused.err.find(')', at) - at - marker.size());
  const CliResult streamed =
      run("-q extract field:gyroid:512 --iso 0 --memory " + budget + " -o streamed.ply", limit);
  ASSERT_EQ(streamed.code, 0) << "--memory " << budget << ": " << streamed.err;
  ASSERT_EQ(run("-q extract field:gyroid:512 --iso 0 -o in_core.ply").code, 0);
  EXPECT_TRUE(slurp(dir_ / "streamed.ply") == slurp(dir_ / "in_core.ply"))
      << "--memory " << budget << " gave another file than in core";
}

// `info` on a volume larger than the process can hold reads it slab by slab and says what an
// unlimited run says. Before, it read the volume whole: refused by its allocation under
// ulimit -v, killed part-way through by the OOM killer under overcommit.
TEST_F(CliLimits, InfoOnAVolumeLargerThanMemoryReadsItSlabBySlab) {
#ifdef ISOTILE_SANITIZED
  GTEST_SKIP() << "sanitizer runtimes reserve terabytes of address space: ulimit -v cannot apply";
#endif
  // 128 MiB of uint8 waves, and 97 MiB of address space.
  const std::filesystem::path raw = dir_ / "waves_512x512x512_uint8.raw";
  {
    std::vector<char> plane(512 * 512);
    std::ofstream f(raw, std::ios::binary);
    for (int z = 0; z < 512; ++z) {
      for (int y = 0; y < 512; ++y)
        for (int x = 0; x < 512; ++x)
          plane[static_cast<std::size_t>(y * 512 + x)] =
              static_cast<char>((x * 7 + y * 3 + z * 5 + (x * y) % 11) % 251);
      f.write(plane.data(), static_cast<std::streamsize>(plane.size()));
    }
  }
  const std::string limit = "ulimit -v 100000 &&";
  for (const std::string json : {"", " --json"}) {
    const CliResult whole = run("info " + raw.filename().string() + json);
    ASSERT_EQ(whole.code, 0) << whole.err;
    const CliResult slabs = run("info " + raw.filename().string() + json, limit);
    ASSERT_EQ(slabs.code, 0) << slabs.err;
    EXPECT_EQ(slabs.out, whole.out);
    EXPECT_NE(whole.out.find("134217728"), std::string::npos) << whole.out;
  }
  std::filesystem::remove(raw);
  // Float samples, whose isovalue histogram holds many values a bin: a second pass counts the 16
  // bins (512 MiB of a field under 488 MiB of address space).
  const CliResult whole = run("info field:gyroid:512 --json");
  ASSERT_EQ(whole.code, 0) << whole.err;
  const CliResult slabs = run("info field:gyroid:512 --json", "ulimit -v 500000 &&");
  ASSERT_EQ(slabs.code, 0) << slabs.err;
  EXPECT_EQ(slabs.out, whole.out);
}

}  // namespace
