// What the isotile program's subcommands share: quiet mode and the progress lines on stderr, the
// input options of `extract` and `info`, writing text to a file or standard output, the process's
// memory and thread policy, and (under MPI) the launcher's session. Errors are one line on stderr
// and a non-zero exit (tiler/main.cpp).
#pragma once

#include <CLI/CLI.hpp>
#include <chrono>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/mesh/mesh_io.h"
#include "core/progress.h"
#include "core/volume/volume_io.h"
#ifdef ISOTILE_HAVE_MPI
#include "tiler/mpi_extract.h"
#include "tiler/stats_json.h"
#endif

namespace isotile::cli {

using Clock = std::chrono::steady_clock;

extern bool g_quiet;
// The library's progress as lines on stderr (print_progress in cli_common.cpp).
extern Progress g_progress;

#ifdef ISOTILE_HAVE_MPI
// Set when started by an MPI launcher (tiler/mpi_launch.h); only rank 0 reports.
extern std::optional<MpiSession> g_mpi;
// Inside extract_distributed: an error that is not an AgreedError is this rank's alone, and the
// other ranks wait for it in a collective, so the job is aborted.
extern bool g_distributed;
#endif

// A number option's check on its text, before CLI11 converts it: a finite number in (0, max]
// (strtod's syntax, the whole text), or with `integer` digits only (CLI11 would wrap -1 into an
// unsigned option).
CLI::Validator positive_number(double max, const std::string& description, bool integer = false);

// A text option's check: not empty (an unset shell variable, `--memory "$MEM"`, would otherwise
// read as the option not given: an in-core run, a field's own isovalue).
CLI::Validator non_empty();

// A run's files, as (what, path) with its `inputs` inputs first: InputError naming both when an
// output is another output or an input (the later write would replace the first file, or the
// input, and the run would say it succeeded). "-" and empty paths are skipped.
void check_distinct_files(const std::vector<std::pair<std::string, std::string>>& files,
                          std::size_t inputs);

// One progress line on stderr ("isotile: MESSAGE") unless --quiet.
void progress(const std::string& message);

// Options describing how to read a raw input, shared by `extract` and `info`.
struct InputArgs {
  std::string input;
  std::string dims, type, spacing, origin, endian = "little", series;

  void add_to(CLI::App& app);
  RawOptions raw_options() const;
};

// Standard output's buffered writes that failed (a full disk, a closed pipe's EPIPE, /dev/full):
// an IoError, so that the run exits 1 instead of 0 with the output lost. `earlier_errno`: the
// reason of a write that failed before the flush (errno then), where the flush sets none.
void flush_stdout(int earlier_errno = 0);

// `text` into `path` (written whole or not at all), or to standard output for "-".
void write_text(const std::string& path, const std::string& text);

// The process's allocator keeps freed blocks for reuse (see cli_common.cpp) and TBB's workers
// start while the input is read: one-shot runs of the program, not the library's business.
void keep_freed_memory_for_reuse();
void start_worker_threads();

}  // namespace isotile::cli
