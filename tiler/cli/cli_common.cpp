#include "tiler/cli/cli_common.h"

#include <malloc.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <limits>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "tiler/input_options.h"

namespace isotile::cli {

bool g_quiet = false;

#ifdef ISOTILE_HAVE_MPI
std::optional<MpiSession> g_mpi;
bool g_distributed = false;
#endif

void progress(const std::string& message) {
  if (!g_quiet) std::fprintf(stderr, "isotile: %s\n", message.c_str());
}

void check_distinct_files(const std::vector<std::pair<std::string, std::string>>& files,
                          std::size_t inputs) {
  // "-" is standard output, which the shell may have pointed at one of the files
  // (`--stats - > mesh.ply`): compared as the file it is.
  const auto file = [](const std::string& p) { return p == "-" ? std::string("/dev/stdout") : p; };
  for (std::size_t i = inputs; i < files.size(); ++i)
    for (std::size_t j = 0; j < i; ++j) {
      const auto& [what, path] = files[i];
      const auto& [other, other_path] = files[j];
      if (path.empty() || other_path.empty()) continue;
      if (same_file(file(path), file(other_path)))
        throw InputError(
            what + " " + path + " is the same file as " + other +
            (j < inputs ? " (it would be replaced)" : " (one would replace the other)"));
    }
}

CLI::Validator non_empty() {
  return CLI::Validator(
      [](std::string& s) { return s.empty() ? std::string("must not be empty") : std::string(); },
      "");
}

CLI::Validator positive_number(double max, const std::string& description, bool integer) {
  return CLI::Validator(
      [max, description, integer](std::string& s) {
        char* end = nullptr;
        const double v = std::strtod(s.c_str(), &end);
        const bool digits = !s.empty() && s.find_first_not_of("0123456789") == std::string::npos;
        const bool ok = end != s.c_str() && *end == '\0' && std::isfinite(v) && v > 0 && v <= max &&
                        (!integer || digits);
        return ok ? std::string() : "must be " + description + ", got '" + s + "'";
      },
      description);
}

// The library's progress as lines on stderr: about twenty per stage of a tiled run (one per
// brick done, thinned), else one per tenth of a stage.
namespace {
bool print_progress(const ProgressUpdate& u) {
  static Stage last_stage = Stage::Read;
  static int last_tenth = 0;
  if (u.bricks > 1) {
    const std::int64_t step = std::max<std::int64_t>(1, u.bricks / 20);
    if (u.fraction >= 1 && ((u.brick + 1) % step == 0 || u.brick + 1 == u.bricks))
      progress(std::string(stage_name(u.stage)) + ": " + std::to_string(u.brick + 1) + "/" +
               std::to_string(u.bricks) + " bricks");
    return true;
  }
  const int tenth = static_cast<int>(u.fraction * 10);
  if (u.fraction == 0 || u.stage != last_stage) last_tenth = 0;
  last_stage = u.stage;
  if (tenth > last_tenth) {
    last_tenth = tenth;
    progress(std::string(stage_name(u.stage)) + ": " + std::to_string(tenth * 10) + "%");
  }
  return true;
}
}  // namespace
Progress g_progress{print_progress};

void InputArgs::add_to(CLI::App& app) {
  app.add_option("INPUT", input,
                 "Volume file by extension: NRRD (.nrrd, .nhdr), OpenVDB (.vdb), NIfTI (.nii, "
                 ".nii.gz), MetaImage (.mha, .mhd), TIFF (.tif, .tiff), MRC/CCP4 (.mrc, .mrcs, "
                 ".map, .ccp4), DICOM (.dcm, .ima, or any file with DICOM's DICM marker), raw "
                 "(any other name: NAME_XxYxZ_TYPE.raw[.gz], or --dims and --type; .gz is "
                 "gunzipped); a DICOM or TIFF directory, a numbered TIFF pattern "
                 "(slice_%03d.tif) or a procedural field field:NAME:N (sphere, torus, gyroid, "
                 "csg-box, marschner-lobb)")
      ->required();
  app.add_option("--dims", dims,
                 "Raw input: samples along x,y,z, e.g. 256,256,128 (default: from the file "
                 "name NAME_XxYxZ_TYPE.raw)")
      ->check(non_empty());
  app.add_option("--type", type,
                 "Raw input: int8|uint8|int16|uint16|int32|uint32|float32|float64 (default: "
                 "from the file name)")
      ->check(non_empty());
  app.add_option("--spacing", spacing,
                 "Sample spacing x,y,z, finite and above 0 (overrides the file's; default: the "
                 "file's, 1,1,1 for raw input)")
      ->check(non_empty());
  app.add_option("--origin", origin,
                 "World position x,y,z of the first sample, finite (overrides the file's; "
                 "default: the file's, 0,0,0 for raw input)")
      ->check(non_empty());
  app.add_option("--endian", endian, "Raw input byte order")
      ->check(CLI::IsMember({"little", "big"}));
  app.add_option("--series", series,
                 "DICOM: the SeriesInstanceUID to read where the directory holds several "
                 "(default: the only one)")
      ->check(non_empty());
}

RawOptions InputArgs::raw_options() const {
  RawOptions o = parse_input_text(
      {.dims = dims, .type = type, .spacing = spacing, .origin = origin, .endian = endian});
  o.series = series;
  return o;
}

// Standard output's buffered writes that failed (a full disk, a closed pipe's EPIPE, /dev/full):
// an IoError, so that the run exits 1 instead of 0 with the output lost.
void flush_stdout(int earlier_errno) {
  // std::cout writes through stdout's buffer (synced with stdio), so its flush is stdout's: the
  // first failing flush sets errno, the second only confirms.
  errno = 0;
  std::cout.flush();
  const bool flushed = std::fflush(stdout) == 0;
  const int err = errno != 0 ? errno : earlier_errno;
  if (flushed && !std::ferror(stdout) && std::cout.good()) return;
  throw IoError(std::string("cannot write standard output") +
                (err != 0 ? std::string(": ") + std::strerror(err) : std::string()));
}

void write_text(const std::string& path, const std::string& text) {
  if (path == "-") {
    std::fwrite(text.data(), 1, text.size(), stdout);
    flush_stdout();
    return;
  }
  AtomicFile f(path);
  f.write(text.data(), text.size());
  f.commit();
}

// glibc maps every large block afresh and unmaps it when freed, so each array an extraction
// allocates after freeing another is faulted in and zero-filled by the kernel again. Out of core,
// bricks allocate and free arrays of the same sizes, brick after brick: 2.0M page faults and 4.5 s
// of system time on a 4 GiB volume (docs/tiler.md). In core, the extractors' passes free scratch
// tables before the next allocates (Macet's smoothing tables, then the mesh: 11% of a one-shot
// Macet run on bonsai). Kept on the heap, later arrays reuse the freed pages; peak RSS is the
// same, since the freed arrays were resident at once anyway. One arena: a worker thread's arena
// maps large blocks whatever M_MMAP_MAX says.
void keep_freed_memory_for_reuse() {
#ifdef __GLIBC__
  mallopt(M_ARENA_MAX, 1);
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max());
#endif
}

// TBB creates its worker threads on the first parallel loop, which in a one-shot run is the
// extraction's first pass. Started there, they made cold extractions slower and more scattered
// (engine: DC 35.7 against 27.2 ms, MC 15.0 against 13.3 ms, medians of 13 fresh processes;
// docs/benchmarks.md, "Worker threads started before the read");
// an empty task enqueued before the volume is read starts them while the main thread reads, and
// nothing waits for it. With one thread allowed, an enqueued task would still get a worker of its
// own, so none is asked for.
void start_worker_threads() {
  if (tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism) > 1)
    tbb::this_task_arena::enqueue([] {});
}

}  // namespace isotile::cli
