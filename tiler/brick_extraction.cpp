#include "tiler/brick_extraction.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/brick_sites.h"
#include "core/mesh/mesh_io.h"

namespace isotile {

namespace {

bool contains(const Box3& b, std::int64_t x, std::int64_t y, std::int64_t z) {
  return x >= b.lo[0] && x < b.hi[0] && y >= b.lo[1] && y < b.hi[1] && z >= b.lo[2] && z < b.hi[2];
}

template <class T>
char* put_le(char* p, T v) {
  static_assert(std::endian::native == std::endian::little, "little-endian hosts only");
  std::memcpy(p, &v, sizeof(T));
  return p + sizeof(T);
}

// The two triangles of a quad along the diagonal whose worse triangle is better (0-2 on ties), as
// core/mesh/mesh_quality.h counts them.
std::array<double, 2> quad_quality(const Vec3f& a, const Vec3f& b, const Vec3f& c, const Vec3f& d) {
  const double a0 = radius_ratio(a, b, c), a1 = radius_ratio(a, c, d);
  const double b0 = radius_ratio(a, b, d), b1 = radius_ratio(b, c, d);
  if (std::min(b0, b1) > std::min(a0, a1)) return {b0, b1};
  return {a0, a1};
}

// Writes [begin, end) of `records` (fixed-size) whose file offsets are offset(i); consecutive
// records that are also consecutive in the file go out in one write.
template <class Offset>
void write_runs(const WriteAt& write, const std::vector<char>& records, std::size_t record_bytes,
                std::size_t count, Offset&& offset) {
  std::size_t i = 0;
  while (i < count) {
    std::size_t j = i + 1;
    const std::uint64_t first = offset(i);
    while (j < count && offset(j) == first + (j - i) * record_bytes) ++j;
    write(first, records.data() + i * record_bytes, (j - i) * record_bytes);
    i = j;
  }
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
  plan_ = plan_bricks(n_, reader_.plan_options(opt_.memory));
  vseg_ = std::make_unique<SegmentTable>(n_, plan_.count[0]);
  fseg_ = std::make_unique<SegmentTable>(n_, plan_.count[0]);
  brick_vertices_.assign(static_cast<std::size_t>(plan_.total()), 0);
  brick_faces_.assign(static_cast<std::size_t>(plan_.total()), 0);
  return plan_;
}

void BrickExtraction::count(std::int64_t b) {
  const Box3 cells = plan_.cells(b);
  const BrickCounts counts = reader_.count(cells);
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
  const Box3 cells = plan_.cells(b);
  const auto i = static_cast<std::size_t>(b);
  // The real output is known now: cut a brick whose output would overflow the budget into
  // thinner z-slices.
  const BrickReader::Slicing cut =
      reader_.slice(cells, brick_vertices_[i], brick_faces_[i], opt_.memory);
  const std::int64_t slices = cut.count;
  for (std::int64_t s = 0; s < slices; ++s) {
    Box3 part = cells;
    part.lo[2] = cells.lo[2] + cells.extent(2) * s / slices;
    part.hi[2] = cells.lo[2] + cells.extent(2) * (s + 1) / slices;
    extract_part(part, write, quality);
    ++result.bricks_extracted;
  }
  result.largest_brick_bytes = std::max(result.largest_brick_bytes, cut.bytes);
}

void BrickExtraction::extract_part(const Box3& cells, const WriteAt& write,
                                   QualityAccumulator& quality) {
  const SegmentTable& vseg = *vseg_;
  const VolumeView view = reader_.read(grow(cells, halo_, n_));
  ExtractOptions o = ex_;
  o.cells = cells;
  const Mesh mesh = isotile::extract(view, o);
  const std::vector<std::uint64_t> keys = brick_vertex_keys(view, ex_.iso, layout_, cells);
  if (keys.size() != mesh.positions.size())
    throw Error("brick contract broken: the extractor listed " +
                std::to_string(mesh.positions.size()) + " vertices where " +
                std::to_string(keys.size()) + " were expected");

  // Final index of every listed vertex. Keys are sorted, so a segment's listed vertices are
  // consecutive: a prefix of it when the segment is this brick's column or the next one
  // (Marching Cubes' vertices on the upper x face), a suffix when it is the previous column
  // (Dual Contouring's cells just below the brick).
  const std::int64_t column = plan_.owner(0, cells.lo[0]);
  const Box3 owned = layout_ == SiteLayout::EdgeVertices ? owned_samples(cells, n_) : cells;
  std::vector<std::uint64_t> index(keys.size());
  std::vector<char> is_owned(keys.size());
  const auto nx = static_cast<std::uint64_t>(n_[0]), ny = static_cast<std::uint64_t>(n_[1]);
  const std::uint64_t per_site = keys_per_site(layout_);
  for (std::size_t g0 = 0; g0 < keys.size();) {
    const std::uint64_t lin = keys[g0] / per_site;
    const auto y = static_cast<std::int64_t>(lin / nx % ny);
    const auto z = static_cast<std::int64_t>(lin / nx / ny);
    const std::int64_t col = plan_.owner(0, static_cast<std::int64_t>(lin % nx));
    const std::size_t seg = vseg.index(y, z, col);
    std::size_t g1 = g0 + 1;
    for (; g1 < keys.size(); ++g1) {
      const std::uint64_t l = keys[g1] / per_site;
      if (l / nx != lin / nx || plan_.owner(0, static_cast<std::int64_t>(l % nx)) != col) break;
    }
    const std::uint64_t first = vseg.offset(seg) + (col < column ? vseg.count(seg) - (g1 - g0) : 0);
    for (std::size_t i = g0; i < g1; ++i) {
      index[i] = first + (i - g0);
      const std::uint64_t l = keys[i] / per_site;
      is_owned[i] = contains(owned, static_cast<std::int64_t>(l % nx), y, z);
    }
    g0 = g1;
  }
  if (opt_.format == MeshFormat::Ply) write_vertices(mesh, index, is_owned, write);
  write_faces(cells, mesh, index, write, quality);
}

void BrickExtraction::write_vertices(const Mesh& mesh, const std::vector<std::uint64_t>& index,
                                     const std::vector<char>& is_owned, const WriteAt& write) {
  std::vector<std::size_t> owned;
  owned.reserve(index.size());
  for (std::size_t i = 0; i < index.size(); ++i)
    if (is_owned[i]) owned.push_back(i);
  std::vector<char> records(owned.size() * vertex_bytes_);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, owned.size()), [&](const auto& r) {
    for (std::size_t o = r.begin(); o != r.end(); ++o) {
      char* p = records.data() + o * vertex_bytes_;
      for (float c : frame_position(opt_.frame, mesh.positions[owned[o]])) p = put_le(p, c);
      if (ex_.normals)
        for (float c : frame_normal(opt_.frame, mesh.normals[owned[o]])) p = put_le(p, c);
    }
  });
  write_runs(write, records, vertex_bytes_, owned.size(),
             [&](std::size_t o) { return vertex_base_ + index[owned[o]] * vertex_bytes_; });
}

void BrickExtraction::write_faces(const Box3& cells, const Mesh& mesh,
                                  const std::vector<std::uint64_t>& index, const WriteAt& write,
                                  QualityAccumulator& quality) {
  const SegmentTable& fseg = *fseg_;
  const std::int64_t column = plan_.owner(0, cells.lo[0]);
  const std::size_t total = quads_ ? mesh.quads.size() : mesh.triangles.size();
  // Faces come row by row; each row's faces start at its segment's offset.
  std::vector<std::uint64_t> first;  // file index of each face
  first.reserve(total);
  for (std::int64_t z = cells.lo[2]; z < cells.hi[2]; ++z)
    for (std::int64_t y = cells.lo[1]; y < cells.hi[1]; ++y) {
      const std::size_t seg = fseg.index(y, z, column);
      const std::uint64_t n = fseg.count(seg);
      if (first.size() + n > total)
        throw Error("brick contract broken: the extractor made fewer faces than counted");
      for (std::uint64_t f = 0; f < n; ++f) first.push_back(fseg.offset(seg) + f);
    }
  if (first.size() != total)
    throw Error("brick contract broken: the extractor made " + std::to_string(total) +
                " faces where " + std::to_string(first.size()) + " were counted");
  const auto& P = mesh.positions;
  const MeshFrame& fr = opt_.frame;
  // The written corners: in the world frame, and mirrored faces reversed (as apply_frame does).
  const auto W = [&](std::uint32_t v) { return frame_position(fr, P[v]); };
  std::vector<char> records(total * face_bytes_);
  std::vector<double> q(opt_.quality ? total * (quads_ ? 2 : 1) : 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, total), [&](const auto& r) {
    for (std::size_t f = r.begin(); f != r.end(); ++f) {
      char* p = records.data() + f * face_bytes_;
      if (quads_) {
        Quad v = mesh.quads[f];
        if (!q.empty()) {
          const auto pair = quad_quality(P[v[0]], P[v[1]], P[v[2]], P[v[3]]);
          q[2 * f] = pair[0];
          q[2 * f + 1] = pair[1];
        }
        if (fr.flip) std::swap(v[1], v[3]);
        if (opt_.format == MeshFormat::Ply)
          put_face(p, v.data(), 4, index);
        else
          put_stl_triangle(put_stl_triangle(p, W(v[0]), W(v[1]), W(v[2])), W(v[0]), W(v[2]),
                           W(v[3]));
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
  write_runs(write, records, face_bytes_, total,
             [&](std::size_t f) { return face_base_ + first[f] * face_bytes_; });
  written_faces_ += total;
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
