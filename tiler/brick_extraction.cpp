#include "tiler/brick_extraction.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/brick_sites.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"

namespace isotile {

namespace {

template <class T>
char* put_le(char* p, T v) {
  static_assert(std::endian::native == std::endian::little, "little-endian hosts only");
  std::memcpy(p, &v, sizeof(T));
  return p + sizeof(T);
}

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace

BrickExtraction::BrickExtraction(VolumeSource& source, const TiledOptions& options)
    : opt_(options), n_(source.dims), reader_(source, options.extract) {
  if (options.format != MeshFormat::Ply && options.format != MeshFormat::Stl)
    throw InputError(
        "streamed (--memory) output is binary PLY or STL: their records have a "
        "fixed size, so each brick can be written in place");
  ex_ = reader_.extract();
  layout_ = reader_.layout();
  quads_ = ex_.method == Method::DualContouring && ex_.keep_quads;
  face_mult_ = ex_.method == Method::DualContouring && !ex_.keep_quads ? 2 : 1;
  halo_ = reader_.halo();
}

bool BrickExtraction::empty_volume() const {
  return n_[0] < 2 || n_[1] < 2 || n_[2] < 2;
}

const BrickPlan& BrickExtraction::plan() {
  // The two tables hold a count for every sample row per brick column, whole: the planner weighs
  // them against cube bricks' many columns (brick_plan.h, column_bytes).
  const std::uint64_t per_column = 2 * SegmentTable::column_bytes(n_);
  const auto options = [&] {
    BrickPlanOptions po = reader_.plan_options(opt_.memory, opt_.max_read_amplification);
    po.column_bytes = per_column;
    return po;
  };
  try {
    plan_ = plan_bricks(n_, options());
  } catch (const InputError&) {
    // Too small a budget for a second brick's samples: one brick at a time.
    if (!overlap_) throw;
    set_overlap(false);
    plan_ = plan_bricks(n_, options());
  }
  // No estimate counts the tables: where even the plan's take more than a quarter of the budget
  // (whole rows of a large volume at a small budget), the run goes over it, and says so first.
  const std::uint64_t table_bytes = per_column * static_cast<std::uint64_t>(plan_.count[0]);
  if (static_cast<double>(table_bytes) > kColumnShare * static_cast<double>(opt_.memory)) {
    const std::int64_t columns = plan_.count[0];
    say_warning(opt_.warn, "the memory budget of " + std::to_string(opt_.memory) +
                               " bytes leaves out the tiler's tables of counts, " +
                               std::to_string(table_bytes) +
                               " bytes for this plan (16 per sample row per " +
                               "brick column: " + std::to_string(n_[1] * n_[2]) + " rows, " +
                               std::to_string(columns) + (columns == 1 ? " column" : " columns") +
                               "); the run goes over the budget" +
                               (columns == 1 ? "" : " (a larger one plans fewer columns)"));
  }
  vseg_ = std::make_unique<SegmentTable>(n_, plan_.count[0]);
  fseg_ = std::make_unique<SegmentTable>(n_, plan_.count[0]);
  brick_vertices_.assign(static_cast<std::size_t>(plan_.total()), 0);
  brick_faces_.assign(static_cast<std::size_t>(plan_.total()), 0);
  return plan_;
}

TiledResult::Stages BrickExtraction::stages() const {
  TiledResult::Stages s = stages_;
  s.read = reader_.read_seconds();
  return s;
}

void BrickExtraction::set_overlap(bool on) {
  overlap_ = on;
  reader_.set_read_ahead(on);
}

void BrickExtraction::count(std::int64_t b) {
  std::vector<char> buffer;
  count(b, read_for_count(b, buffer));
}

VolumeView BrickExtraction::read_for_count(std::int64_t b, std::vector<char>& buffer) {
  return reader_.read(reader_.count_box(plan_.cells(b)), buffer);
}

void BrickExtraction::count(std::int64_t b, const VolumeView& view) {
  const Box3 cells = plan_.cells(b);
  const auto t0 = Clock::now();
  const BrickCounts counts = reader_.count(cells, view);
  stages_.count += since(t0);
  const std::int64_t xb = plan_.owner(0, cells.lo[0]);
  brick_vertices_[static_cast<std::size_t>(b)] = scatter(counts.vertices, xb, 1, *vseg_);
  brick_faces_[static_cast<std::size_t>(b)] = scatter(counts.faces, xb, face_mult_, *fseg_);
}

// Copies one brick's row counts into the table; returns their sum.
std::uint64_t BrickExtraction::scatter(const RowCounts& rc, std::int64_t column, std::uint64_t mult,
                                       SegmentTable& table) {
  std::uint64_t sum = 0;
  const std::int64_t ny = rc.box.extent(1);
  for (std::size_t r = 0; r < rc.count.size(); ++r) {
    const std::int64_t y = rc.box.lo[1] + static_cast<std::int64_t>(r) % ny;
    const std::int64_t z = rc.box.lo[2] + static_cast<std::int64_t>(r) / ny;
    table[table.index(y, z, column)] = rc.count[r] * mult;
    sum += rc.count[r] * mult;
  }
  return sum;
}

void BrickExtraction::scan(TiledResult& result) {
  vertices_ = result.vertices = vseg_->scan();
  faces_ = result.faces = fseg_->scan();
  result.triangles = quads_ ? 2 * result.faces : result.faces;
  // The file: header, then every record at its final offset.
  index64_ = result.vertices > std::numeric_limits<std::uint32_t>::max();
  if (opt_.format == MeshFormat::Ply) {
    vertex_base_ = header().size();
    vertex_bytes_ = ex_.normals ? 24 : 12;
    face_base_ = vertex_base_ + result.vertices * vertex_bytes_;
    face_bytes_ = 1 + (quads_ ? 4 : 3) * (index64_ ? 8 : 4);
  } else {
    if (result.triangles > std::numeric_limits<std::uint32_t>::max())
      throw InputError("binary STL holds at most 2^32 - 1 triangles; this mesh has " +
                       std::to_string(result.triangles) + ": write PLY instead");
    face_base_ = kStlHeaderBytes;
    face_bytes_ = (quads_ ? 2 : 1) * kStlTriangleBytes;
  }
  // The real output is known now: a brick whose output would overflow the budget is cut into
  // thinner z-slices.
  cuts_ = slice_bricks(
      plan_.total(),
      [&](std::int64_t b) {
        const auto i = static_cast<std::size_t>(b);
        // The part's own face records beyond what estimate() counts for them (a PLY face's 13
        // bytes; 25 with 64-bit indices): an STL triangle takes 50, a DC quad two of them.
        // Uncounted, 2048x2048x512 to STL at --memory 256MiB peaked at up to 1.42 times the
        // budget.
        double extra_per_face =
            std::max(0.0, static_cast<double>(face_bytes_) - BrickReader::kFaceRecordBytes);
        // Records of the part before, still being written while this one is extracted.
        if (overlap_ && brick_faces_[i] > 0)
          extra_per_face += static_cast<double>(face_bytes_) +
                            static_cast<double>(vertex_bytes_ * brick_vertices_[i]) /
                                static_cast<double>(brick_faces_[i]);
        return reader_.slice(plan_.cells(b), brick_vertices_[i], plane_faces(b), opt_.memory,
                             extra_per_face);
      },
      opt_.memory, opt_.warn);
}

std::vector<std::uint64_t> BrickExtraction::plane_faces(std::int64_t b) const {
  const Box3 cells = plan_.cells(b);
  const Box3 rows = owned_samples(cells, n_);
  const std::int64_t column = plan_.owner(0, cells.lo[0]);
  std::vector<std::uint64_t> planes(static_cast<std::size_t>(cells.extent(2)), 0);
  for (std::int64_t z = rows.lo[2]; z < rows.hi[2]; ++z) {
    // The volume's last sample plane, which the last brick along z owns, has no cells above.
    const std::int64_t plane = std::min(z, cells.hi[2] - 1) - cells.lo[2];
    for (std::int64_t y = rows.lo[1]; y < rows.hi[1]; ++y)
      planes[static_cast<std::size_t>(plane)] += fseg_->count(fseg_->index(y, z, column));
  }
  return planes;
}

std::string BrickExtraction::header() const {
  if (opt_.format == MeshFormat::Ply)
    return ply_header(vertices_, faces_, ex_.normals, false, index64_);
  char stl[kStlHeaderBytes];
  stl_header(stl, quads_ ? 2 * faces_ : faces_);
  return std::string(stl, sizeof(stl));
}

void BrickExtraction::extract(std::int64_t b, const WriteAt& write, QualityAccumulator& quality,
                              TiledResult& result) {
  std::vector<char> buffer;
  for (const Box3& part : parts(b, result))
    this->write(extract_part(part, read_part(part, buffer), quality), write);
}

std::vector<Box3> BrickExtraction::parts(std::int64_t b, TiledResult& result) {
  const Box3 cells = plan_.cells(b);
  const BrickReader::Slicing& cut = cuts_[static_cast<std::size_t>(b)];
  const std::int64_t slices = cut.count;
  std::vector<Box3> out;
  for (std::int64_t s = 0; s < slices; ++s) out.push_back(z_slice(cells, s, slices));
  result.bricks_extracted += slices;
  result.largest_brick_bytes = std::max(result.largest_brick_bytes, cut.bytes);
  return out;
}

VolumeView BrickExtraction::read_part(const Box3& part, std::vector<char>& buffer) {
  return reader_.read(grow(part, halo_, n_), buffer);
}

void BrickExtraction::write(const BrickRecords& records, const WriteAt& write) {
  const auto t0 = Clock::now();
  records.write(write);
  stages_.write += since(t0);
}

void BrickRecords::write(const WriteAt& write) const {
  for (const Run& r : runs) write(r.offset, data.get() + r.begin, r.bytes);
}

// Edge vertices need no keys: a brick lists, per point row of its closed box, the vertices its
// column's segment of that row counted (whichever brick counted it), then the 0-3 on the edges
// of the sample at x = cells.hi.x, which open the next column's segment.
void BrickExtraction::edge_vertex_index(const VolumeView& view, const Box3& cells,
                                        std::vector<std::uint64_t>& index,
                                        std::vector<char>& is_owned) {
  const SegmentTable& vseg = *vseg_;
  const std::vector<std::uint8_t> upper = upper_x_edge_vertices(view, ex_.iso, cells);
  const std::int64_t column = plan_.owner(0, cells.lo[0]);
  const Box3 owned = owned_samples(cells, n_);
  const std::int64_t ny = cells.extent(1) + 1;
  const std::size_t rows = upper.size();
  const auto segment = [&](std::size_t r, std::int64_t col) {
    const auto ri = static_cast<std::int64_t>(r);
    return vseg.index(cells.lo[1] + ri % ny, cells.lo[2] + ri / ny, col);
  };
  std::vector<std::uint64_t> start(rows + 1);
  for (std::size_t r = 0; r < rows; ++r)
    start[r + 1] = start[r] + vseg.count(segment(r, column)) + upper[r];
  if (start[rows] != index.size())
    throw Error("brick contract broken: the extractor listed " + std::to_string(index.size()) +
                " vertices where " + std::to_string(start[rows]) + " were counted");
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rows), [&](const auto& range) {
    for (std::size_t r = range.begin(); r != range.end(); ++r) {
      const auto ri = static_cast<std::int64_t>(r);
      const std::int64_t y = cells.lo[1] + ri % ny, z = cells.lo[2] + ri / ny;
      const char own = y < owned.hi[1] && z < owned.hi[2];
      const std::size_t seg = segment(r, column);
      const std::uint64_t n = vseg.count(seg);
      for (std::uint64_t i = 0; i < n; ++i) {
        index[start[r] + i] = vseg.offset(seg) + i;
        is_owned[start[r] + i] = own;
      }
      if (upper[r] == 0) continue;
      const std::uint64_t next = vseg.offset(segment(r, column + 1));
      for (std::uint64_t i = 0; i < upper[r]; ++i) {
        index[start[r] + n + i] = next + i;
        is_owned[start[r] + n + i] = 0;
      }
    }
  });
}

// Cell vertices (Dual Contouring) by their keys.
void BrickExtraction::keyed_vertex_index(const VolumeView& view, const Box3& cells,
                                         std::vector<std::uint64_t>& index,
                                         std::vector<char>& is_owned) {
  const std::vector<std::uint64_t> keys = brick_vertex_keys(view, ex_.iso, layout_, cells);
  if (keys.size() != index.size())
    throw Error("brick contract broken: the extractor listed " + std::to_string(index.size()) +
                " vertices where " + std::to_string(keys.size()) + " were expected");
  // Final index of every listed vertex. Keys are sorted, so a segment's listed vertices are
  // consecutive: a prefix of it when the segment is this brick's column or the next one
  // (Marching Cubes' vertices on the upper x face), a suffix when it is the previous column
  // (Dual Contouring's cells just below the brick). Rows are independent; within a row, column
  // and ownership are key ranges, so no key is divided.
  const SegmentTable& vseg = *vseg_;
  const std::int64_t column = plan_.owner(0, cells.lo[0]);
  const Box3 owned = layout_ == SiteLayout::EdgeVertices ? owned_samples(cells, n_) : cells;
  const auto nx = static_cast<std::uint64_t>(n_[0]), ny = static_cast<std::uint64_t>(n_[1]);
  const std::uint64_t per_site = keys_per_site(layout_);
  const std::uint64_t row_keys = nx * per_site;
  const auto key_at = [&](std::uint64_t row, std::int64_t x) {
    return row * row_keys + static_cast<std::uint64_t>(x) * per_site;
  };
  if (!keys.empty()) {
    const std::uint64_t row0 = keys.front() / row_keys, row1 = keys.back() / row_keys;
    tbb::parallel_for(tbb::blocked_range<std::uint64_t>(row0, row1 + 1), [&](const auto& range) {
      for (std::uint64_t row = range.begin(); row != range.end(); ++row) {
        const auto lo = std::lower_bound(keys.begin(), keys.end(), key_at(row, 0));
        const auto hi = std::lower_bound(lo, keys.end(), key_at(row + 1, 0));
        if (lo == hi) continue;
        const auto y = static_cast<std::int64_t>(row % ny), z = static_cast<std::int64_t>(row / ny);
        const bool row_owned =
            y >= owned.lo[1] && y < owned.hi[1] && z >= owned.lo[2] && z < owned.hi[2];
        const std::uint64_t own_lo = key_at(row, owned.lo[0]), own_hi = key_at(row, owned.hi[0]);
        for (auto g0 = lo; g0 != hi;) {
          const auto x = static_cast<std::int64_t>((*g0 - key_at(row, 0)) / per_site);
          const std::int64_t col = plan_.owner(0, x);
          const std::int64_t col_end =
              col + 1 < plan_.count[0] ? (col + 1) * plan_.brick[0] : n_[0];
          const auto g1 = std::lower_bound(g0, hi, key_at(row, col_end));
          const std::size_t seg = vseg.index(y, z, col);
          const auto n = static_cast<std::uint64_t>(g1 - g0);
          const std::uint64_t first = vseg.offset(seg) + (col < column ? vseg.count(seg) - n : 0);
          for (auto g = g0; g != g1; ++g) {
            const auto i = static_cast<std::size_t>(g - keys.begin());
            index[i] = first + static_cast<std::uint64_t>(g - g0);
            is_owned[i] = row_owned && *g >= own_lo && *g < own_hi;
          }
          g0 = g1;
        }
      }
    });
  }
}

BrickRecords BrickExtraction::extract_part(const Box3& cells, const VolumeView& view,
                                           QualityAccumulator& quality, Progress* progress) {
  ExtractOptions o = ex_;
  o.cells = cells;
  o.progress = progress;
  auto t0 = Clock::now();
  BackendChoice ran;
  const Mesh mesh = isotile::extract(view, o, &ran);
  stages_.extract += since(t0);
  if (ran.gpu) accumulate_gpu_report(gpu_, *ran.gpu);
  t0 = Clock::now();
  std::vector<std::uint64_t> index(mesh.positions.size());
  std::vector<char> is_owned(mesh.positions.size());
  if (layout_ == SiteLayout::EdgeVertices)
    edge_vertex_index(view, cells, index, is_owned);
  else
    keyed_vertex_index(view, cells, index, is_owned);
  stages_.index += since(t0);

  t0 = Clock::now();
  BrickRecords out;
  std::vector<std::size_t> first_vertex;
  std::size_t vertex_bytes = 0;
  if (opt_.format == MeshFormat::Ply) {
    vertex_bytes = vertex_runs(index, is_owned, out.runs, first_vertex);
  }
  const std::size_t vertex_runs_end = out.runs.size();
  const std::size_t faces = quads_ ? mesh.quads.size() : mesh.triangles.size();
  face_runs(cells, faces, out.runs, vertex_bytes);
  out.size = vertex_bytes + faces * face_bytes_;
  // Not value-initialised: every byte is written below.
  out.data.reset(new char[out.size]);
  fill_vertex_records(mesh, out.runs, vertex_runs_end, first_vertex, out.data.get());
  fill_face_records(mesh, index, out.data.get() + vertex_bytes, quality);
  written_faces_ += faces;
  stages_.records += since(t0);
  return out;
}

// Runs of owned vertices consecutive both in the mesh and in the file; returns their bytes.
std::size_t BrickExtraction::vertex_runs(const std::vector<std::uint64_t>& index,
                                         const std::vector<char>& is_owned,
                                         std::vector<BrickRecords::Run>& runs,
                                         std::vector<std::size_t>& first_vertex) const {
  std::size_t bytes = 0;
  for (std::size_t i = 0; i < index.size();) {
    if (!is_owned[i]) {
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    while (j < index.size() && is_owned[j] && index[j] == index[i] + (j - i)) ++j;
    const std::size_t n = (j - i) * vertex_bytes_;
    runs.push_back({vertex_base_ + index[i] * vertex_bytes_, bytes, n});
    first_vertex.push_back(i);
    bytes += n;
    i = j;
  }
  return bytes;
}

// Faces come cell row by cell row, each row's at its segment's offset: one run per row, rows
// merged where their segments follow each other in the file.
void BrickExtraction::face_runs(const Box3& cells, std::size_t total,
                                std::vector<BrickRecords::Run>& runs, std::size_t begin) const {
  const SegmentTable& fseg = *fseg_;
  const std::int64_t column = plan_.owner(0, cells.lo[0]);
  const std::size_t first_run = runs.size();
  std::size_t at = 0;  // faces placed
  for (std::int64_t z = cells.lo[2]; z < cells.hi[2]; ++z)
    for (std::int64_t y = cells.lo[1]; y < cells.hi[1]; ++y) {
      const std::size_t seg = fseg.index(y, z, column);
      const std::uint64_t n = fseg.count(seg);
      if (n == 0) continue;
      if (at + n > total)
        throw Error("brick contract broken: the extractor made fewer faces than counted");
      const std::uint64_t offset = face_base_ + fseg.offset(seg) * face_bytes_;
      BrickRecords::Run* last = runs.size() > first_run ? &runs.back() : nullptr;
      if (last && last->offset + last->bytes == offset)
        last->bytes += n * face_bytes_;
      else
        runs.push_back({offset, begin + at * face_bytes_, n * face_bytes_});
      at += n;
    }
  if (at != total)
    throw Error("brick contract broken: the extractor made " + std::to_string(total) +
                " faces where " + std::to_string(at) + " were counted");
}

void BrickExtraction::fill_vertex_records(const Mesh& mesh,
                                          const std::vector<BrickRecords::Run>& runs,
                                          std::size_t end,
                                          const std::vector<std::size_t>& first_vertex,
                                          char* out) const {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, end), [&](const auto& range) {
    for (std::size_t r = range.begin(); r != range.end(); ++r) {
      char* p = out + runs[r].begin;
      const std::size_t n = runs[r].bytes / vertex_bytes_;
      for (std::size_t v = first_vertex[r]; v < first_vertex[r] + n; ++v) {
        for (float c : frame_position(opt_.frame, mesh.positions[v])) p = put_le(p, c);
        if (ex_.normals)
          for (float c : frame_normal(opt_.frame, mesh.normals[v])) p = put_le(p, c);
      }
    }
  });
}

void BrickExtraction::fill_face_records(const Mesh& mesh, const std::vector<std::uint64_t>& index,
                                        char* out, QualityAccumulator& quality) const {
  const std::size_t total = quads_ ? mesh.quads.size() : mesh.triangles.size();
  const auto& P = mesh.positions;
  const MeshFrame& fr = opt_.frame;
  // The written corners: in the world frame, and mirrored faces reversed (as apply_frame does).
  const auto W = [&](std::uint32_t v) { return frame_position(fr, P[v]); };
  // The ratios in parallel, added in face order after (the sums are integers anyway): one
  // accumulator's 2^16 bins per thread would cost more memory than small bricks have.
  std::vector<double> q(opt_.quality ? total * (quads_ ? 2 : 1) : 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, total), [&](const auto& r) {
    for (std::size_t f = r.begin(); f != r.end(); ++f) {
      char* p = out + f * face_bytes_;
      if (quads_) {
        Quad v = mesh.quads[f];
        if (!q.empty()) {
          const auto pair = split_quad(P, v).quality;
          q[2 * f] = pair[0];
          q[2 * f + 1] = pair[1];
        }
        if (fr.flip) std::swap(v[1], v[3]);
        if (opt_.format == MeshFormat::Ply) {
          put_face(p, v.data(), 4, index);
        } else {
          // The better diagonal by the grid-frame positions (the pipeline refuses quads with
          // STL; a caller of the tiler alone may still ask for them).
          const auto [s, t] = split_quad(P, v).triangles;
          put_stl_triangle(put_stl_triangle(p, W(s[0]), W(s[1]), W(s[2])), W(t[0]), W(t[1]),
                           W(t[2]));
        }
      } else {
        Tri t = mesh.triangles[f];
        if (!q.empty()) q[f] = radius_ratio(P[t[0]], P[t[1]], P[t[2]]);
        if (fr.flip) std::swap(t[1], t[2]);
        if (opt_.format == MeshFormat::Ply)
          put_face(p, t.data(), 3, index);
        else
          put_stl_triangle(p, W(t[0]), W(t[1]), W(t[2]));
      }
    }
  });
  for (double x : q) quality.add(x);
}

char* BrickExtraction::put_face(char* p, const std::uint32_t* v, int n,
                                const std::vector<std::uint64_t>& index) const {
  *p++ = static_cast<char>(n);
  for (int i = 0; i < n; ++i) {
    if (index64_)
      p = put_le(p, index[v[i]]);
    else
      p = put_le(p, static_cast<std::uint32_t>(index[v[i]]));
  }
  return p;
}

}  // namespace isotile
