// Out-of-core extraction: a volume is cut into bricks that fit a memory budget, extracted brick by
// brick and streamed into one mesh file that is byte-identical to a whole-volume extraction
// written by write_mesh, for any budget.
//
// Two passes over the bricks. The first only classifies samples and counts, per grid row and per
// column of bricks, the vertices and faces each brick owns (a vertex belongs to the brick that
// owns its site: its edge's lower sample, or its cell; a face to the brick of its cell or edge).
// An exclusive scan of those counts in global key order gives every vertex and face its final
// index before any is placed. The second pass extracts each brick in brick mode, turns its local
// indices into final ones (core/extract/brick_sites.h) and writes its records straight to their
// offsets in the output file, so nothing but the current brick and the count tables is held in
// memory. The file is written to a temporary name and renamed when complete
// (core/mesh/atomic_file.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "core/extract/extract.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/simplify/simplify.h"
#include "tiler/brick_plan.h"
#include "tiler/volume_source.h"

namespace isotile {

struct TiledOptions {
  ExtractOptions extract;    // method, iso, normals, ... (cells is set per brick)
  std::uint64_t memory = 0;  // budget for one brick's working set, bytes
  // From this budget on, the next brick is read and the last one written while a brick is
  // extracted (two in flight, each planned to fit the budget together). Below it, where a few
  // MiB of allocator slack between two bricks matter, one brick at a time.
  std::uint64_t overlap_min_memory = std::uint64_t{256} << 20;
  // BrickPlanOptions::max_read_amplification: a budget whose bricks would read the volume more
  // times over is refused, naming the budget that keeps to it. 0: no limit.
  double max_read_amplification = 64;
  MeshFormat format = MeshFormat::Ply;  // binary PLY or binary STL (fixed-size records)
  bool quality = true;                  // accumulate radius-ratio statistics of the faces
  // Below 1: simplify to this fraction of the faces, brick by brick (tiler/tiled_simplify.h).
  double simplify = 1;
  double simplify_min_quality = 0.3;  // SimplifyOptions::min_quality
  // Maps the written positions, normals and windings into the volume's world frame (inactive:
  // the grid frame), exactly as the in-core writes do; statistics stay in the grid frame.
  MeshFrame frame;
  // When the count pass finds no face (no pair of samples straddles the isovalue): false throws
  // InputError naming the samples' range (found by one more pass, on that error only) before
  // the output is touched; true writes the empty mesh.
  bool allow_empty = true;
  // Told of each brick counted and extracted (Stage::Count, Stage::Extract, the brick set);
  // null: nobody listens. Cancelling throws Cancelled and leaves no output file.
  Progress* progress = nullptr;
  // Told once (core/progress.h), after the count and before any brick is extracted, when the run
  // must go over the budget: a brick whose surface is so dense that even its one-cell z-slices
  // overflow it (the mesh is still exact; largest_brick_bytes says it too). Null: stderr.
  Warn warn;
};

struct TiledResult {
  BrickPlan plan;
  Backend backend = Backend::Cpu;     // where the bricks ran
  std::int64_t bricks_extracted = 0;  // plan.total() plus extra z-slices of bricks that were cut
  std::uint64_t vertices = 0, faces = 0, triangles = 0;
  std::uint64_t largest_brick_bytes = 0;  // estimated working set of the largest brick run
  double seconds_count = 0, seconds_extract = 0;
  // Where the passes' time goes: busy seconds of each stage summed over the bricks (reading the
  // samples, counting a brick, extracting it, turning its keys into final indices, formatting its
  // records, writing them). Stages that overlap in time add up to more than the wall time.
  // Unset where they were not timed (the simplifying tiler's bricks).
  struct Stages {
    double read = 0, count = 0, extract = 0, index = 0, records = 0, write = 0;
  };
  std::optional<Stages> stages;
  // With simplification: faces as extracted (triangles), the simplifier's counts, the seam
  // cells (a grid shifted by half a brick) and the time of the seam pass.
  std::uint64_t triangles_extracted = 0;
  SimplifyStats simplify;
  Index3 seam_cells{0, 0, 0};
  // The pieces the seam pass simplified: the seam cells, those the budget cannot hold whole
  // counted by their z-parts.
  std::int64_t seam_parts = 0;
  double seconds_seams = 0;
  // Radius ratio over all triangles (quads as their two triangles along the better diagonal).
  // min, mean and degenerate are exact; q001, q01 and median come from a histogram of 2^16 bins
  // (within 1.6e-5).
  QualityStats quality;
  // A GL backend's reports of its bricks, summed (upload, stages, program cache); unset where
  // the CPU made the mesh.
  std::optional<GpuReport> gpu;
};

// Throws InputError for a budget too small or a format without fixed-size records, and whatever
// the source, the extractor or the writer throws; the output is then left untouched. With
// options.simplify < 1 the work goes to extract_tiled_simplified (tiler/tiled_simplify.h),
// whose output is not identical to an in-core run's.
TiledResult extract_tiled(VolumeSource& source, const TiledOptions& options,
                          const std::filesystem::path& output);

}  // namespace isotile
