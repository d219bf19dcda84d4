// The passes of the out-of-core extraction, one brick at a time, shared by the single-process
// tiler (tiled_extract.cpp) and the distributed one (mpi_extract.cpp): count a brick's owned
// vertices and faces per grid row into the segment tables, scan them into final offsets, then
// extract a brick and hand its records to a writer at their final file offsets. Which process
// runs which brick, and in which order, does not change a byte of the output. Internal to the
// tiler.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tiler/brick_reader.h"
#include "tiler/tiled_extract.h"

namespace isotile {

// Per-row, per-brick-column counts, turned into offsets by an exclusive scan: entry
// (y, z, column) is where that segment's records start in the file's global order.
class SegmentTable {
 public:
  SegmentTable(const Index3& n, std::int64_t columns)
      : ny_(n[1]), columns_(columns), v_(static_cast<std::size_t>(n[1] * n[2] * columns) + 1) {}
  // Bytes per brick column: a count per sample row (y, z).
  static std::uint64_t column_bytes(const Index3& n) {
    return sizeof(std::uint64_t) * static_cast<std::uint64_t>(n[1] * n[2]);
  }
  std::size_t index(std::int64_t y, std::int64_t z, std::int64_t column) const {
    return static_cast<std::size_t>((z * ny_ + y) * columns_ + column);
  }
  std::uint64_t& operator[](std::size_t i) { return v_[i]; }
  std::uint64_t offset(std::size_t i) const { return v_[i]; }
  std::uint64_t count(std::size_t i) const { return v_[i + 1] - v_[i]; }
  // The counts before scan(): a process that counted only some bricks holds zeros elsewhere,
  // and every entry has one owner, so adding the tables of all processes gathers them.
  std::vector<std::uint64_t>& values() { return v_; }
  std::uint64_t scan() {
    std::uint64_t sum = 0;
    for (auto& x : v_) {
      const std::uint64_t c = x;
      x = sum;
      sum += c;
    }
    return sum;
  }

 private:
  std::int64_t ny_, columns_;
  std::vector<std::uint64_t> v_;
};

// Receives `n` bytes of records for file offset `offset`.
using WriteAt = std::function<void(std::uint64_t offset, const char* data, std::size_t n)>;

// The records of one brick (or z-slice of one), formatted and placed: runs of bytes that are
// consecutive in the file. They own their bytes, so they can be written while the next brick is
// extracted.
struct BrickRecords {
  struct Run {
    std::uint64_t offset;      // in the file
    std::size_t begin, bytes;  // in data
  };
  std::unique_ptr<char[]> data;
  std::size_t size = 0;
  std::vector<Run> runs;

  void write(const WriteAt& write) const;
};

class BrickExtraction {
 public:
  // InputError for an output format without fixed-size records.
  BrickExtraction(VolumeSource& source, const TiledOptions& options);

  // True when the volume has fewer than two samples along an axis (no cells, an empty mesh).
  bool empty_volume() const;
  // Plans the bricks and sizes the tables; InputError for a budget too small.
  const BrickPlan& plan();
  const BrickPlan& current_plan() const { return plan_; }
  const ExtractOptions& extract_options() const { return ex_; }

  // Read the next brick while this one is counted or extracted (every brick's working set then
  // counts a second sample buffer; and records of the brick before while this one is
  // extracted). Set before plan().
  // plan() turns it off where the budget does not hold two bricks' samples.
  void set_overlap(bool on);
  bool overlap() const { return overlap_; }

  // Pass 1 for brick b: its owned vertices and faces into the tables and the per-brick sums.
  void count(std::int64_t b);
  // The same in two steps, so that reading one brick can overlap counting another: the samples
  // counting brick b needs, read into `buffer`, then the count from them.
  VolumeView read_for_count(std::int64_t b, std::vector<char>& buffer);
  void count(std::int64_t b, const VolumeView& view);
  SegmentTable& vertex_table() { return *vseg_; }
  SegmentTable& face_table() { return *fseg_; }
  std::vector<std::uint64_t>& brick_vertices() { return brick_vertices_; }
  std::vector<std::uint64_t>& brick_faces() { return brick_faces_; }
  // Once every brick is counted (in these tables): the exclusive scan, the totals and the
  // file's layout, and each brick's z-slices (slice_bricks(): a budget that even one-cell slices
  // of the densest brick overflow goes to TiledOptions::warn). InputError for binary STL past
  // 2^32 - 1 triangles.
  void scan(TiledResult& result);
  // The file's header (PLY or STL), written at offset 0.
  std::string header() const;

  // Pass 2 for brick b: extracts it (in z-slices when its counted output would overflow the
  // budget) and writes its owned vertices and all its faces through `write`. Updates
  // bricks_extracted and largest_brick_bytes.
  void extract(std::int64_t b, const WriteAt& write, QualityAccumulator& quality,
               TiledResult& result);
  // The same in steps: the parts (z-slices) brick b runs as (counted in `result`), each read
  // into `buffer`, extracted into its records, then written (BrickRecords::write).
  std::vector<Box3> parts(std::int64_t b, TiledResult& result);
  VolumeView read_part(const Box3& part, std::vector<char>& buffer);
  // `progress`: told of the core extraction's progress (a child Progress for the brick).
  BrickRecords extract_part(const Box3& part, const VolumeView& view, QualityAccumulator& quality,
                            Progress* progress = nullptr);
  void write(const BrickRecords& records, const WriteAt& write);
  std::uint64_t written_faces() const { return written_faces_; }
  // Busy seconds per stage so far (read from the reader's clock).
  TiledResult::Stages stages() const;
  // The GL backends' reports of the parts extracted so far, summed; unset where the CPU ran.
  const std::optional<GpuReport>& gpu() const { return gpu_; }

 private:
  std::uint64_t scatter(const RowCounts& rc, std::int64_t column, std::uint64_t mult,
                        SegmentTable& table);
  // Brick b's faces per z-plane of its cells, from the face table once scanned.
  std::vector<std::uint64_t> plane_faces(std::int64_t b) const;
  // The final index of every vertex a brick lists, and whether the brick owns (writes) it.
  void edge_vertex_index(const VolumeView& view, const Box3& cells,
                         std::vector<std::uint64_t>& index, std::vector<char>& is_owned);
  void keyed_vertex_index(const VolumeView& view, const Box3& cells,
                          std::vector<std::uint64_t>& index, std::vector<char>& is_owned);
  // Runs of the owned vertices' records (bytes from 0), and of the faces' (from `begin`).
  std::size_t vertex_runs(const std::vector<std::uint64_t>& index,
                          const std::vector<char>& is_owned, std::vector<BrickRecords::Run>& runs,
                          std::vector<std::size_t>& first_vertex) const;
  void face_runs(const Box3& cells, std::size_t total, std::vector<BrickRecords::Run>& runs,
                 std::size_t begin) const;
  void fill_vertex_records(const Mesh& mesh, const std::vector<BrickRecords::Run>& runs,
                           std::size_t end, const std::vector<std::size_t>& first_vertex,
                           char* out) const;
  void fill_face_records(const Mesh& mesh, const std::vector<std::uint64_t>& index, char* out,
                         QualityAccumulator& quality) const;
  char* put_face(char* p, const std::uint32_t* v, int n,
                 const std::vector<std::uint64_t>& index) const;

  const TiledOptions& opt_;
  Index3 n_;
  BrickReader reader_;
  ExtractOptions ex_;
  SiteLayout layout_ = SiteLayout::EdgeVertices;
  bool quads_ = false;
  std::uint64_t face_mult_ = 1;
  int halo_ = 2;
  BrickPlan plan_;
  std::unique_ptr<SegmentTable> vseg_, fseg_;
  std::vector<std::uint64_t> brick_vertices_, brick_faces_;
  std::vector<BrickReader::Slicing> cuts_;  // each brick's z-slices, from scan()
  std::uint64_t vertices_ = 0, faces_ = 0;
  bool index64_ = false;
  std::uint64_t vertex_base_ = 0, vertex_bytes_ = 12, face_base_ = 0, face_bytes_ = 13;
  std::uint64_t written_faces_ = 0;
  bool overlap_ = false;
  TiledResult::Stages stages_;
  std::optional<GpuReport> gpu_;
};

}  // namespace isotile
