// What the tiler's passes share: the halo and the bytes a method needs per brick, the planner's
// options for them, a buffer the bricks' samples are read into, and a streamed radius-ratio
// accumulator. Internal to the tiler (tiled_extract.cpp, tiled_simplify.cpp).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/extract/brick_sites.h"
#include "core/extract/extract.h"
#include "core/mesh/mesh_quality.h"
#include "tiler/brick_plan.h"
#include "tiler/volume_source.h"

namespace isotile {

// Samples a brick reads: its cells' samples grown by `halo`, clipped to the volume.
Box3 grow(const Box3& cells, int halo, const Index3& n);

// The samples a brick owns: its cells' lower corners, plus the volume's last sample plane for the
// last brick along an axis.
Box3 owned_samples(const Box3& cells, const Index3& n);

// Slice s of `count` z-slices of a brick: its columns, its z-range cut evenly.
Box3 z_slice(const Box3& cells, std::int64_t s, std::int64_t count);

class BrickReader {
 public:
  // Resolves the backend once, so that every brick runs on the same one.
  BrickReader(VolumeSource& source, const ExtractOptions& extract);

  const ExtractOptions& extract() const { return ex_; }
  SiteLayout layout() const { return layout_; }
  int halo() const { return halo_; }
  const Index3& dims() const { return n_; }
  VolumeSource& source() { return src_; }

  // Whether the next brick's samples are read while this one is worked on: every brick's working
  // set then counts a second sample buffer. Set before plan_options().
  void set_read_ahead(bool on) { read_ahead_ = on; }
  // The planner's options for `memory` bytes a brick (and BrickPlanOptions::
  // max_read_amplification); tells the source how much consecutive bricks overlap.
  BrickPlanOptions plan_options(std::uint64_t memory, double max_read_amplification);
  // A view of global box `box`, read into the shared buffer (valid until the next read).
  VolumeView read(const Box3& box);
  // The same into `buffer` (grown as needed, never shrunk; valid until its next use).
  VolumeView read(const Box3& box, std::vector<char>& buffer);
  // Seconds spent in read() so far.
  double read_seconds() const { return read_seconds_; }
  // Reads what counting a brick needs (its owned samples and one more) and counts the vertices
  // and faces it owns; InputError for NaN or infinite samples.
  BrickCounts count(const Box3& cells);
  // The same in two steps: the samples counting needs, then the count from a view of them.
  Box3 count_box(const Box3& cells) const;
  BrickCounts count(const Box3& cells, const VolumeView& view) const;
  // A face's record as estimate() counts it: a PLY triangle's 13 bytes and their runs. A writer
  // whose records are larger adds the difference to `extra_per_face`.
  static constexpr double kFaceRecordBytes = 16;
  // Working set of one brick: samples with halo and their bits, the mesh, keys, final indices,
  // the records being written, and `extra_per_face` bytes for each face (a later stage's).
  std::uint64_t estimate(const Box3& cells, std::uint64_t vertices, std::uint64_t faces,
                         double extra_per_face = 0) const;
  // Once a brick's output is counted: into how many z-slices (z_slice(), same columns, so the
  // segment tables still apply) it must be cut for each to fit `memory`, and the largest slice's
  // estimate. `plane_faces`: the brick's faces per z-plane of its cells (cells.extent(2) of
  // them), so that a slice is estimated with the faces it holds, its vertices in proportion.
  // `odd`: never an even count (which would cut at the brick's middle plane).
  struct Slicing {
    std::int64_t count;
    std::uint64_t bytes;
    // Where even one-cell slices overflow the budget: what they would need, the least this brick
    // can; 0 where the slices fit.
    std::uint64_t least = 0;
  };
  Slicing slice(const Box3& cells, std::uint64_t vertices,
                const std::vector<std::uint64_t>& plane_faces, std::uint64_t memory,
                double extra_per_face = 0, bool odd = false) const;

 private:
  std::uint64_t kept_bytes() const;
  double state_bytes_per_sample() const;
  std::size_t sample_bytes() const;

  VolumeSource& src_;
  ExtractOptions ex_;
  Index3 n_;
  SiteLayout layout_ = SiteLayout::EdgeVertices;
  int halo_ = 2;
  std::vector<char> buffer_;
  double read_seconds_ = 0;
  bool read_ahead_ = false;
};

// Once every brick of a plan is counted: the slicing of bricks 0..bricks-1 (`slice_brick`), and
// one line to `warn` (say_warning(), core/progress.h), before anything is extracted, where some
// brick's one-cell z-slices still overflow `memory` (a surface denser than the budget allows),
// naming the largest slice's bytes. The run then goes over the budget.
std::vector<BrickReader::Slicing> slice_bricks(
    std::int64_t bricks, const std::function<BrickReader::Slicing(std::int64_t)>& slice_brick,
    std::uint64_t memory, const Warn& warn);

// Radius-ratio statistics of a stream of triangles: min, mean and the degenerate count are
// exact; q001, q01 and the median come from a histogram of 2^16 bins (within 1.6e-5). The sum
// behind the mean is core's RatioSum (integer), so min, mean, the degenerate count and the
// histogram are the same bits as in core, whichever process counted which triangles.
class QualityAccumulator {
 public:
  void add(double q);
  QualityStats stats() const;

  // For adding accumulators of several processes: the counters (triangles, degenerate, the sum
  // in four 32-bit limbs, the 20 histogram bins, the fine bins), to be added element by element,
  // and the bits of the minimum and maximum (non-negative doubles order like their bits), to be
  // reduced by min and max.
  std::vector<std::uint64_t> counters() const;
  std::uint64_t min_bits() const;
  std::uint64_t max_bits() const;
  static QualityAccumulator from_parts(const std::vector<std::uint64_t>& counters,
                                       std::uint64_t min_bits, std::uint64_t max_bits);

 private:
  double quantile(double p) const;
  std::uint64_t triangles_ = 0, degenerate_ = 0;
  double min_ = 1, max_ = 0;
  RatioSum sum_;
  std::vector<std::uint64_t> bins_ = std::vector<std::uint64_t>(1 << 16);
  // The 20 bins of QualityStats::histogram, counted per triangle (histogram_bin) as in core: a
  // fine bin straddles a 0.05 edge (2^16 is not a multiple of 20), so they cannot be summed from
  // bins_.
  std::array<std::uint64_t, 20> histogram_{};
};

}  // namespace isotile
