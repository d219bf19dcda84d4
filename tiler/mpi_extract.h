// Distributed out-of-core extraction over MPI: `mpirun -np K isotile extract ... --memory SIZE`.
//
// Every rank plans the same bricks. The count pass runs on contiguous blocks of bricks, one per
// rank; the ranks' segment tables (each entry counted by one brick) are added across ranks, so
// every rank then holds the whole table and scans it in global key order: every vertex's and
// face's final index is known everywhere before a record is written. The extract pass deals the
// bricks out by their counted output (longest first, to the least loaded rank), and each rank
// writes its records at their final offsets into one file with MPI-IO. The file is byte-identical
// to the single-process run whatever the rank count: a brick's records do not depend on who
// extracts it.
//
// The file is written under a temporary name (rank 0's AtomicFile) and renamed by rank 0 only
// when every rank succeeded. Each phase ends with the ranks agreeing on success: a rank that
// failed (an unreadable brick, a bad sample) makes every rank stop, the temporary is removed and
// rank 0 reports the first failure with its rank and brick. A rank that dies ends the job through
// the launcher, whose SIGTERM makes rank 0 remove the temporary.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/volume/volume_io.h"
#include "tiler/tiled_extract.h"

namespace isotile {

// MPI_Init on construction, MPI_Finalize on destruction. Construct only under a launcher
// (tiler/mpi_launch.h). Throws InputError when the launcher started several tasks that MPI sees
// as one each (srun without a PMI plugin).
class MpiSession {
 public:
  MpiSession(int* argc, char*** argv);
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
  // Ends every rank of the job (MPI_Abort): for a failure the other ranks cannot know of.
  [[noreturn]] void abort(int code);
  int rank = 0, size = 1;
};

// A failure every rank knows of (agreed on collectively): rank 0 carries the message to print;
// the other ranks' copies are empty and print nothing. All ranks exit normally.
struct AgreedError : Error {
  using Error::Error;
};

struct RankTimes {
  double seconds_count = 0, seconds_extract = 0;
  std::int64_t bricks_counted = 0, bricks_extracted = 0;
  std::uint64_t triangles = 0;  // written by this rank
  double planned_cost = 0;      // the balance model's cost of its extract bricks
  double peak_rss_mb = 0;
};

struct DistributedResult {
  TiledResult tiled;  // the whole mesh (on rank 0)
  Index3 dims{0, 0, 0};
  ScalarType type = ScalarType::Float32;
  bool source_in_memory = false;
  bool world_frame = false;  // the mesh was written in the volume's world frame
  int ranks = 1;
  // Rank 0 only: every rank's times, and per brick the measured seconds of each pass.
  std::vector<RankTimes> rank_times;
  std::vector<double> brick_seconds_count, brick_seconds_extract;
  std::vector<std::uint64_t> brick_faces;  // counted, per brick (the balance model's input)
  // Slowest rank's extract time over the mean (1: perfect); the same for the model's costs.
  double load_imbalance = 1, planned_imbalance = 1;
};

// The balance model: a brick's extract cost in units of one face, from its cells and its counted
// faces (docs/tiler.md#distributed-runs-mpi).
double brick_cost(const Box3& cells, std::uint64_t faces);

// Deals bricks to `ranks` ranks: the costliest first, each to the rank with the least cost so far
// (ties: lower brick index first, lower rank). Returns each brick's rank.
std::vector<int> balance_bricks(const std::vector<double>& cost, int ranks);

// Runs on every rank of MPI_COMM_WORLD; `progress` is called on rank 0 for its own bricks.
// Throws AgreedError on every rank for a failure of any rank, after removing the temporary.
// `world_frame`: the mesh is written in the volume's world frame (options.frame is set from the
// source each rank opens), else as options.frame says.
DistributedResult extract_distributed(const std::string& input, const RawOptions& raw,
                                      const TiledOptions& options, bool world_frame,
                                      const std::filesystem::path& output);

}  // namespace isotile
