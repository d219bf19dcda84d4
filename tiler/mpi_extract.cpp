#include "tiler/mpi_extract.h"

#include <mpi.h>
#include <sys/resource.h>
#include <sys/statvfs.h>
#ifdef __SANITIZE_ADDRESS__
#include <sanitizer/lsan_interface.h>
#endif

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "tiler/brick_extraction.h"
#include "tiler/mpi_launch.h"
#include "tiler/source_histogram.h"
#include "tiler/volume_source.h"

namespace isotile {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

// A brick's extract cost per cell, in units of one face: reading and classifying its samples
// against a face's vertex keys, sorting and records. tests/benchmarks/bench_mpi.sh fits the
// per-brick extract seconds to both: bonsai, MC, 216 bricks of 43^3 cells gave 0.099.
constexpr double kCellCost = 0.1;

std::string describe(const Box3& c) {
  auto range = [&](int a) {
    return "[" + std::to_string(c.lo[a]) + ", " + std::to_string(c.hi[a]) + ")";
  };
  return "cells " + range(0) + " x " + range(1) + " x " + range(2);
}

// The other ranks' hold on rank 0's temporary: removed on SIGINT/SIGTERM too (the launcher
// sends SIGTERM to every rank when one dies, which may be rank 0).
class TrackedTemporary {
 public:
  explicit TrackedTemporary(const std::string& path) : slot_(track_temporary(path)) {}
  ~TrackedTemporary() { untrack_temporary(slot_); }
  TrackedTemporary(const TrackedTemporary&) = delete;
  TrackedTemporary& operator=(const TrackedTemporary&) = delete;

 private:
  int slot_;
};

// Test hook (tests/test_mpi.cpp only): ISOTILE_MPI_TEST_FAIL=BRICK:PASS makes the rank that
// runs that brick fail on it, PASS being `count` or `extract` (an IoError, as an unreadable brick
// gives) or `kill` (the rank dies of SIGKILL in the extract pass, as a crashed node would).
struct InjectedFailure {
  std::int64_t brick = -1;
  std::string pass;
};
std::optional<InjectedFailure> injected_failure() {
  const char* v = std::getenv("ISOTILE_MPI_TEST_FAIL");
  if (!v || !*v) return std::nullopt;
  const std::string s(v);
  const auto a = s.find(':');
  if (a == std::string::npos) return std::nullopt;
  return InjectedFailure{std::atoll(s.substr(0, a).c_str()), s.substr(a + 1)};
}

// A rank's GL report (core's GpuReport, from the bricks its GL backend ran) as text for
// Ranks::gather(), and back: JSON, whose numbers nlohmann writes in the shortest form that reads
// back to the same double. "" for a rank whose bricks ran on the CPU or that ran none.
std::string encode_gpu_report(const std::optional<GpuReport>& g) {
  if (!g) return "";
  nlohmann::ordered_json stages = nlohmann::ordered_json::array();
  for (const auto& [stage, seconds] : g->seconds) stages.push_back({stage, seconds});
  return nlohmann::ordered_json{{"seconds", stages},
                                {"upload_bytes", g->upload_bytes},
                                {"upload_seconds", g->upload_seconds},
                                {"context_seconds", g->context_seconds},
                                {"loaded", g->programs_loaded},
                                {"compiled", g->programs_compiled},
                                {"rejected", g->programs_rejected},
                                {"cache_off", g->program_cache_off}}
      .dump();
}

GpuReport decode_gpu_report(const std::string& text) {
  const auto j = nlohmann::json::parse(text);
  GpuReport g;
  for (const auto& s : j.at("seconds"))
    g.seconds.emplace_back(s.at(0).get<std::string>(), s.at(1).get<double>());
  g.upload_bytes = j.at("upload_bytes").get<std::uint64_t>();
  g.upload_seconds = j.at("upload_seconds").get<double>();
  g.context_seconds = j.at("context_seconds").get<double>();
  g.programs_loaded = j.at("loaded").get<int>();
  g.programs_compiled = j.at("compiled").get<int>();
  g.programs_rejected = j.at("rejected").get<int>();
  g.program_cache_off = j.at("cache_off").get<std::string>();
  return g;
}

class Ranks {
 public:
  Ranks() {
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
  }
  int rank() const { return rank_; }
  int size() const { return size_; }

  // Every rank calls this at the end of a phase with its error ("" for none). When any failed,
  // all throw AgreedError: rank 0's names the first failing rank, or no rank when every rank
  // failed alike (a bad option, an unreadable input).
  void agree(const std::string& error) const {
    int bad = error.empty() ? 0 : 1, any = 0;
    MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    if (!any) return;
    const std::vector<std::string> errors = gather(error.substr(0, 4096));
    if (rank_ != 0) throw AgreedError("");
    int first = -1, failed = 0;
    bool alike = true;
    for (int r = 0; r < size_; ++r) {
      if (errors[r].empty()) {
        alike = false;
        continue;
      }
      ++failed;
      if (first < 0)
        first = r;
      else if (errors[r] != errors[first])
        alike = false;
    }
    const std::string& message = errors[first];
    if (alike) throw AgreedError(message);
    throw AgreedError(
        "rank " + std::to_string(first) + " of " + std::to_string(size_) + ", " + message +
        (failed > 1 ? " (" + std::to_string(failed - 1) + " more ranks failed)" : ""));
  }

  // Every rank's `text` on rank 0, in rank order (other ranks get an empty list).
  std::vector<std::string> gather(const std::string& text) const {
    const int len = static_cast<int>(text.size());
    std::vector<int> lens(static_cast<std::size_t>(size_));
    MPI_Gather(&len, 1, MPI_INT, lens.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
    std::vector<int> displs(static_cast<std::size_t>(size_));
    std::exclusive_scan(lens.begin(), lens.end(), displs.begin(), 0);
    std::string all(rank_ == 0 ? static_cast<std::size_t>(displs.back() + lens.back()) : 0, '\0');
    MPI_Gatherv(text.data(), len, MPI_CHAR, all.data(), lens.data(), displs.data(), MPI_CHAR, 0,
                MPI_COMM_WORLD);
    std::vector<std::string> out;
    if (rank_ == 0)
      for (int r = 0; r < size_; ++r) out.push_back(all.substr(displs[r], lens[r]));
    return out;
  }

  // Runs `fn` and agrees on its outcome.
  template <class Fn>
  void phase(Fn&& fn) const {
    std::string error;
    try {
      fn();
    } catch (const std::bad_alloc&) {
      error = "out of memory";
    } catch (const std::exception& e) {
      error = e.what();
      if (error.empty()) error = "unknown error";
    }
    agree(error);
  }

  // Adds `v` across ranks, in place; in pieces, as MPI counts are ints.
  void sum(std::vector<std::uint64_t>& v) const {
    constexpr std::size_t kPiece = std::size_t{1} << 26;
    for (std::size_t i = 0; i < v.size(); i += kPiece)
      MPI_Allreduce(MPI_IN_PLACE, v.data() + i, static_cast<int>(std::min(kPiece, v.size() - i)),
                    MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
  }
  void sum(std::vector<double>& v) const {
    constexpr std::size_t kPiece = std::size_t{1} << 26;
    for (std::size_t i = 0; i < v.size(); i += kPiece)
      MPI_Allreduce(MPI_IN_PLACE, v.data() + i, static_cast<int>(std::min(kPiece, v.size() - i)),
                    MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  }

 private:
  int rank_ = 0, size_ = 1;
};

std::string mpi_error(int code) {
  char text[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(code, text, &len);
  return std::string(text, static_cast<std::size_t>(len));
}

// The temporary, opened by every rank for positioned writes.
class MpiFile {
 public:
  MpiFile(const std::string& path, const std::filesystem::path& target) : target_(target) {
    const int rc =
        MPI_File_open(MPI_COMM_WORLD, path.c_str(), MPI_MODE_WRONLY, MPI_INFO_NULL, &fh_);
    if (rc != MPI_SUCCESS) {
      fh_ = MPI_FILE_NULL;
      throw IoError("cannot write " + target_.string() + " (MPI-IO): " + mpi_error(rc));
    }
  }
  bool is_open() const { return fh_ != MPI_FILE_NULL; }
  // MPI-IO says how many bytes went, not why the rest did not: a full file system is the usual
  // cause, and the one a user can act on.
  std::string short_write_reason() const {
    struct statvfs fs {};
    const std::filesystem::path folder =
        target_.has_parent_path() ? target_.parent_path() : std::filesystem::path(".");
    if (::statvfs(folder.c_str(), &fs) == 0 && fs.f_bavail * fs.f_frsize < (std::uint64_t{1} << 20))
      return std::strerror(ENOSPC);
    return "short write";
  }
  void write_at(std::uint64_t offset, const char* data, std::size_t n) {
    constexpr std::size_t kPiece = std::size_t{1} << 30;
    while (n > 0) {
      const std::size_t piece = std::min(n, kPiece);
      MPI_Status status;
      const int rc = MPI_File_write_at(fh_, static_cast<MPI_Offset>(offset), data,
                                       static_cast<int>(piece), MPI_BYTE, &status);
      int done = 0;
      if (rc == MPI_SUCCESS) MPI_Get_count(&status, MPI_BYTE, &done);
      if (rc != MPI_SUCCESS || done != static_cast<int>(piece))
        throw IoError("cannot write " + target_.string() +
                      " (MPI-IO): " + (rc != MPI_SUCCESS ? mpi_error(rc) : short_write_reason()));
      offset += piece;
      data += piece;
      n -= piece;
    }
  }
  // Collective: every rank's data reaches the disk, then the handle is closed.
  std::string close() {
    std::string error;
    int rc = MPI_File_sync(fh_);
    if (rc != MPI_SUCCESS) error = "cannot write " + target_.string() + ": " + mpi_error(rc);
    rc = MPI_File_close(&fh_);
    if (rc != MPI_SUCCESS && error.empty())
      error = "cannot write " + target_.string() + ": " + mpi_error(rc);
    fh_ = MPI_FILE_NULL;
    return error;
  }

 private:
  std::filesystem::path target_;
  MPI_File fh_ = MPI_FILE_NULL;
};

}  // namespace

MpiSession::MpiSession(int* argc, char*** argv) {
  int provided = 0;
  // TBB's workers never call MPI: the main thread is the only one that does.
  MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &provided);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  const long tasks = launcher_task_count();
  if (size == 1 && tasks > 1)
    throw InputError("the launcher started " + std::to_string(tasks) +
                     " tasks but MPI sees each alone: start them with a PMI plugin (e.g. `srun "
                     "--mpi=pmix`) or with mpirun");
}

MpiSession::~MpiSession() {
#ifdef __SANITIZE_ADDRESS__
  // MPI_Finalize unloads OpenMPI's components (dlclose), so what they leave allocated at exit has
  // no module left to name it by, and no suppression can single it out. LeakSanitizer's one check
  // runs here instead, while they are loaded (isotile's own objects are gone by now; the exit
  // check is then skipped); tests/lsan_openmpi.supp names OpenMPI's libraries.
  __lsan_do_leak_check();
#endif
  MPI_Finalize();
}

void MpiSession::abort(int code) {
  remove_pending_temporaries();
  MPI_Abort(MPI_COMM_WORLD, code);
  std::_Exit(code);
}

double brick_cost(const Box3& cells, std::uint64_t faces) {
  const double n = static_cast<double>(cells.extent(0)) * static_cast<double>(cells.extent(1)) *
                   static_cast<double>(cells.extent(2));
  return kCellCost * n + static_cast<double>(faces);
}

std::vector<int> balance_bricks(const std::vector<double>& cost, int ranks) {
  std::vector<std::size_t> order(cost.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return cost[a] > cost[b]; });
  std::vector<double> load(static_cast<std::size_t>(ranks), 0.0);
  std::vector<int> owner(cost.size(), 0);
  for (std::size_t b : order) {
    const auto r =
        static_cast<std::size_t>(std::min_element(load.begin(), load.end()) - load.begin());
    owner[b] = static_cast<int>(r);
    load[r] += cost[b];
  }
  return owner;
}

DistributedResult extract_distributed(const std::string& input, const RawOptions& raw,
                                      const TiledOptions& requested, bool world_frame,
                                      const std::filesystem::path& output) {
  TiledOptions options = requested;
  const Ranks mpi;
  const int me = mpi.rank(), ranks = mpi.size();
  if (me != 0) options.warn = [](const std::string&) {};  // every rank would say the same
  DistributedResult out;
  out.ranks = ranks;
  TiledResult& result = out.tiled;
  RankTimes mine;
  const std::optional<InjectedFailure> inject = injected_failure();
  auto injected = [&](std::int64_t b, const char* pass) {
    if (!inject || inject->brick != b || inject->pass != pass) return;
    if (inject->pass == "kill") std::raise(SIGKILL);
    throw IoError("injected failure (ISOTILE_MPI_TEST_FAIL)");
  };

  std::unique_ptr<VolumeSource> source;
  std::unique_ptr<BrickExtraction> bricks;
  mpi.phase([&] {
    if (options.simplify < 1)
      throw InputError(
          "--simplify is not distributed: its result depends on the brick plan and its seam "
          "pass needs neighbouring bricks; run it without mpirun");
    // Ranks write their bricks at their offsets (MPI-IO): a device or FIFO cannot take that.
    check_output(output, true);
    source = open_volume_source(input, raw, options.memory);
    check_grid_geometry(source->dims, source->spacing, source->origin, source->world, input);
    // Rank 0's; the others' warn is silent.
    warn_coarse_positions(source->dims, source->spacing, source->origin,
                          world_frame ? source->world : std::nullopt, options.warn);
    if (world_frame) options.frame = mesh_frame(source->origin, source->world);
    if (source->sequential())
      throw InputError(source->name +
                       ": gzip'd data can only be read front to back, so ranks cannot read their "
                       "own bricks; decompress it first for a distributed run (gunzip a .gz "
                       "file; save a gzip NRRD with raw encoding, e.g. unu save -f nrrd -e raw)");
    bricks = std::make_unique<BrickExtraction>(*source, options);
    out.dims = source->dims;
    out.type = source->type;
    out.source_in_memory = source->in_memory();
    out.world_frame = options.frame.active;
    if (!bricks->empty_volume()) result.plan = bricks->plan();
    result.backend = bricks->extract_options().backend;
  });
  if (bricks->empty_volume()) {
    mpi.phase([&] {
      // No cells, so no face: every rank throws the same error, as below.
      if (!options.allow_empty) {
        throw_no_surface(*source, options.memory, options.extract.iso);
      }
      if (me == 0)
        write_mesh(Mesh{}, output,
                   {.format = options.format, .ascii = false, .write_normals = false});
    });
    return out;
  }
  const std::int64_t total = result.plan.total();
  // Numbered from 1, as the progress lines count bricks.
  auto brick_error = [&](std::int64_t b, const std::exception& e) {
    return "brick " + std::to_string(b + 1) + " of " + std::to_string(total) + " (" +
           describe(result.plan.cells(b)) + "): " + e.what();
  };
  std::vector<double> count_seconds(static_cast<std::size_t>(total)),
      extract_seconds(static_cast<std::size_t>(total));

  // Pass 1: count a contiguous block of bricks; then every rank holds every count.
  auto t0 = Clock::now();
  {
    const std::int64_t lo = total * me / ranks, hi = total * (me + 1) / ranks;
    std::string error;
    for (std::int64_t b = lo; b < hi && error.empty(); ++b) {
      const auto tb = Clock::now();
      try {
        injected(b, "count");
        if (options.progress && me == 0) {
          // Inside the try: a cancel becomes this rank's error, which every rank agrees on.
          options.progress->set_brick(b - lo, hi - lo);
          options.progress->begin(Stage::Count, 1);
        }
        bricks->count(b);
        if (me == 0) progress_advance(options.progress);
      } catch (const std::exception& e) {
        error = brick_error(b, e);
      }
      count_seconds[static_cast<std::size_t>(b)] = since(tb);
      ++mine.bricks_counted;
    }
    // The rank's own work, before the collective waits for the others (with it, every rank's
    // seconds were the slowest's, and load_imbalance was 1 whatever the balance).
    mine.seconds_count = since(t0);
    mpi.agree(error);
  }
  mpi.sum(bricks->vertex_table().values());
  mpi.sum(bricks->face_table().values());
  mpi.sum(bricks->brick_vertices());
  mpi.sum(bricks->brick_faces());
  mpi.phase([&] {
    bricks->scan(result);
    // Every rank has the summed counts, so every rank throws the same error; each finds the
    // samples' range for it by one streaming pass (on this error only).
    if (result.faces == 0 && !options.allow_empty) {
      throw_no_surface(*source, options.memory, options.extract.iso);
    }
  });
  result.seconds_count = since(t0);

  // Who extracts what: balanced by the counted output.
  std::vector<double> cost(static_cast<std::size_t>(total));
  for (std::int64_t b = 0; b < total; ++b)
    cost[static_cast<std::size_t>(b)] =
        brick_cost(result.plan.cells(b), bricks->brick_faces()[static_cast<std::size_t>(b)]);
  const std::vector<int> owner = balance_bricks(cost, ranks);
  std::vector<double> planned(static_cast<std::size_t>(ranks));
  for (std::int64_t b = 0; b < total; ++b)
    planned[static_cast<std::size_t>(owner[static_cast<std::size_t>(b)])] +=
        cost[static_cast<std::size_t>(b)];
  mine.planned_cost = planned[static_cast<std::size_t>(me)];

  // The temporary: rank 0 creates it (registered for removal on SIGINT/SIGTERM) and writes the
  // header; every rank opens it.
  std::unique_ptr<AtomicFile> file;
  std::string temp;
  mpi.phase([&] {
    if (me != 0) return;
    file = std::make_unique<AtomicFile>(output, AtomicFile::Writes::Positioned);
    const std::string header = bricks->header();
    file->write_at(0, header.data(), header.size());
    temp = file->temp_path().string();
  });
  int temp_len = static_cast<int>(temp.size());
  MPI_Bcast(&temp_len, 1, MPI_INT, 0, MPI_COMM_WORLD);
  temp.resize(static_cast<std::size_t>(temp_len));
  MPI_Bcast(temp.data(), temp_len, MPI_CHAR, 0, MPI_COMM_WORLD);
  std::optional<TrackedTemporary> tracked;
  if (me != 0) tracked.emplace(temp);
  std::unique_ptr<MpiFile> mf;
  mpi.phase([&] { mf = std::make_unique<MpiFile>(temp, output); });

  // Pass 2: extract this rank's bricks in ascending order, each straight to its offsets.
  t0 = Clock::now();
  QualityAccumulator quality;
  {
    std::string error;
    const WriteAt write = [&](std::uint64_t offset, const char* data, std::size_t n) {
      mf->write_at(offset, data, n);
    };
    std::int64_t done = 0, todo = 0;
    for (std::int64_t b = 0; b < total; ++b) todo += owner[static_cast<std::size_t>(b)] == me;
    for (std::int64_t b = 0; b < total && error.empty(); ++b) {
      if (owner[static_cast<std::size_t>(b)] != me) continue;
      const auto tb = Clock::now();
      try {
        injected(b, "extract");
        injected(b, "kill");
        if (options.progress && me == 0) {
          options.progress->set_brick(done++, todo);
          options.progress->begin(Stage::Extract, 1);
        }
        bricks->extract(b, write, quality, result);
        if (me == 0) progress_advance(options.progress);
      } catch (const std::exception& e) {
        error = brick_error(b, e);
      }
      extract_seconds[static_cast<std::size_t>(b)] = since(tb);
    }
    // The rank's own work (its bricks' z-slices, as the whole run's bricks_extracted counts
    // them), before MPI_File_close and the agreement wait for the other ranks.
    mine.seconds_extract = since(t0);
    mine.bricks_extracted = result.bricks_extracted;
    const std::string closing = mf->close();
    mpi.agree(error.empty() ? closing : error);
  }
  mine.triangles = bricks->written_faces() * (result.triangles == result.faces ? 1 : 2);

  // Every counted face written, then the rename.
  std::vector<std::uint64_t> written{bricks->written_faces(),
                                     static_cast<std::uint64_t>(result.bricks_extracted)};
  mpi.sum(written);
  result.bricks_extracted = static_cast<std::int64_t>(written[1]);
  mpi.phase([&] {
    source->check_unchanged();
    if (written[0] != result.faces)
      throw Error("distributed extraction wrote " + std::to_string(written[0]) + " faces of " +
                  std::to_string(result.faces) + " counted");
    if (me == 0) file->commit();
  });
  result.seconds_extract = since(t0);

  // The GL backends' reports of every rank, added on rank 0 in rank order as a single process
  // adds its bricks' (the context's start-up: the slowest rank's).
  {
    const std::vector<std::string> reports = mpi.gather(encode_gpu_report(bricks->gpu()));
    for (const std::string& r : reports)
      if (!r.empty()) accumulate_gpu_report(result.gpu, decode_gpu_report(r));
  }

  // The stages' busy seconds, summed over the ranks as one process sums them over its bricks.
  {
    const TiledResult::Stages s = bricks->stages();
    const double mine_stages[6] = {s.read, s.count, s.extract, s.index, s.records, s.write};
    double all[6] = {};
    MPI_Reduce(mine_stages, all, 6, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    if (me == 0)
      result.stages = TiledResult::Stages{all[0], all[1], all[2], all[3], all[4], all[5]};
  }

  // The whole mesh's statistics on rank 0.
  std::uint64_t largest = result.largest_brick_bytes;
  MPI_Reduce(&largest, &result.largest_brick_bytes, 1, MPI_UINT64_T, MPI_MAX, 0, MPI_COMM_WORLD);
  if (options.quality) {
    std::vector<std::uint64_t> counters = quality.counters(), sums(me == 0 ? counters.size() : 0);
    MPI_Reduce(counters.data(), sums.data(), static_cast<int>(counters.size()), MPI_UINT64_T,
               MPI_SUM, 0, MPI_COMM_WORLD);
    std::uint64_t lo = quality.min_bits(), hi = quality.max_bits(), min_bits = 0, max_bits = 0;
    MPI_Reduce(&lo, &min_bits, 1, MPI_UINT64_T, MPI_MIN, 0, MPI_COMM_WORLD);
    MPI_Reduce(&hi, &max_bits, 1, MPI_UINT64_T, MPI_MAX, 0, MPI_COMM_WORLD);
    if (me == 0) result.quality = QualityAccumulator::from_parts(sums, min_bits, max_bits).stats();
  }
  mine.peak_rss_mb = peak_rss_mb();
  // Per rank and per brick (each brick ran on one rank, so adding gathers).
  const double row[7] = {mine.seconds_count,
                         mine.seconds_extract,
                         static_cast<double>(mine.bricks_counted),
                         static_cast<double>(mine.bricks_extracted),
                         static_cast<double>(mine.triangles),
                         mine.planned_cost,
                         mine.peak_rss_mb};
  std::vector<double> rows(me == 0 ? 7 * static_cast<std::size_t>(ranks) : 0);
  MPI_Gather(row, 7, MPI_DOUBLE, rows.data(), 7, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  mpi.sum(count_seconds);
  mpi.sum(extract_seconds);
  if (me == 0) {
    double slowest = 0, mean = 0, planned_max = 0, planned_mean = 0;
    for (int r = 0; r < ranks; ++r) {
      const double* x = rows.data() + 7 * r;
      RankTimes t{x[0],
                  x[1],
                  static_cast<std::int64_t>(x[2]),
                  static_cast<std::int64_t>(x[3]),
                  static_cast<std::uint64_t>(x[4]),
                  x[5],
                  x[6]};
      slowest = std::max(slowest, t.seconds_extract);
      mean += t.seconds_extract / ranks;
      planned_max = std::max(planned_max, t.planned_cost);
      planned_mean += t.planned_cost / ranks;
      out.rank_times.push_back(t);
    }
    out.load_imbalance = mean > 0 ? slowest / mean : 1;
    out.planned_imbalance = planned_mean > 0 ? planned_max / planned_mean : 1;
    out.brick_seconds_count = std::move(count_seconds);
    out.brick_seconds_extract = std::move(extract_seconds);
    out.brick_faces = bricks->brick_faces();
  }
  return out;
}

}  // namespace isotile
