// The brick planner: cuts a volume's cells into a regular 3D grid of bricks whose working set
// (samples with halo, classification bits, expected output) fits a memory budget.
//
// Bricks span whole grid rows (x) and are square in y-z when that leaves them at least 64 cells
// thick: the output orders records x fastest, so such a brick writes each z-plane's rows in one
// run. Otherwise (very wide volumes, small budgets) they are as close to cubes as the volume
// allows, which has the least halo per cell. Sizes are then evened out so that the last brick
// along an axis is not a sliver; nothing is rounded up to a power of two or padded. A source that
// can only be read in order (gzip) gets whole x-y slabs.
#pragma once

#include <cstdint>

#include "core/volume/volume.h"

namespace isotile {

struct BrickPlanOptions {
  std::uint64_t memory = 0;  // bytes for one brick's working set
  int halo = 2;              // samples read beyond a brick's cells on each side
  std::size_t sample_bytes = 1;
  // Sample buffers held at once: 2 when the next brick is read while this one is extracted.
  int sample_buffers = 1;
  // Output expected per cell when planning (vertices, faces, keys and their global indices). The
  // tiler checks every brick's real output (known after its counting pass) against the budget
  // and cuts a brick into thinner z-slices when it would not fit.
  double output_bytes_per_cell = 8;
  bool slabs = false;  // whole x-y slabs (sources read in order)
  // Held besides any brick, whatever its size (a gzip source's planes kept for the next slab).
  std::uint64_t fixed_bytes = 0;
  // The extractor's own state per sample of the view, halo included (Macet displaces every grid
  // vertex of its view; the halo has state but no output).
  double state_bytes_per_sample = 0;
  // The volume's samples: when set, a brick's view is clipped to them (a brick spanning an axis
  // reads no halo there).
  Index3 volume_dims{0, 0, 0};
  // A plan whose bricks, grown by their halo, read the volume more times over than this is
  // refused (read_amplification): its run would take as many times the in-core work. Macet max's
  // halo of 138 samples made 64,000 one-cell bricks of a 41^3 volume (killed unfinished after
  // 300 s; under 1 s in core); gyroid 512 with Macet max reads 9.1 times over at 1 GiB, 63.6 at
  // 512 MiB. 0: no limit (the tests' tiny bricks, which stress the seams).
  double max_read_amplification = 64;
  // Held per brick column besides any brick (the plain tiler's tables of counts, 16 bytes per
  // sample row each): where the cubes' would take more than kColumnShare of the budget, bricks
  // span whole rows (one column) however thin, if those read the volume within
  // max_read_amplification.
  std::uint64_t column_bytes = 0;
};
// The share of the budget that the bytes held per brick column may take (column_bytes).
inline constexpr double kColumnShare = 0.25;

struct BrickPlan {
  Index3 dims{0, 0, 0};   // samples of the volume
  Index3 brick{1, 1, 1};  // cells per brick along each axis (the last brick may be shorter)
  Index3 count{0, 0, 0};  // bricks along each axis

  std::int64_t total() const { return count[0] * count[1] * count[2]; }
  // Cells of brick b; bricks are numbered x fastest, then y, then z.
  Box3 cells(std::int64_t b) const;
  // The brick index along `axis` that owns cell or sample coordinate v (the last sample plane
  // belongs to the last brick).
  std::int64_t owner(int axis, std::int64_t v) const;
};

// Bytes one brick of `cells` cells needs under `options` (samples, bits, expected output, the
// extractor's state).
std::uint64_t brick_bytes(const Index3& cells, const BrickPlanOptions& options);

// Throws InputError when not even a brick of one cell (one cell layer, for slabs) fits, and when
// the bricks that fit, each grown by its halo, would read the volume more than
// max_read_amplification times over (a halo as large as Macet max's, 138 samples, against a
// small budget); either names the least budget that plans (least_memory()), so that a run given
// it is not refused again.
BrickPlan plan_bricks(const Index3& dims, const BrickPlanOptions& options);

// The least `options.memory` for which plan_bricks() gives a plan (the figure its refusals name).
std::uint64_t least_memory(const Index3& dims, BrickPlanOptions options);

// How many times over the bricks of `plan`, each grown by `halo` samples on every side (clipped
// to the volume), read the volume's samples: 1 for one brick; more as bricks get thin against
// their halo.
double read_amplification(const BrickPlan& plan, int halo);

// "256MiB", "1.5GB", "4096" (bytes), "2G" ... -> bytes; InputError naming the text otherwise.
std::uint64_t parse_memory_size(const std::string& text);

}  // namespace isotile
