#include "tiler/brick_reader.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <string>

#include "core/volume/volume_io.h"

namespace isotile {

Box3 grow(const Box3& cells, int halo, const Index3& n) {
  Box3 r;
  for (int a = 0; a < 3; ++a) {
    r.lo[a] = std::max<std::int64_t>(cells.lo[a] - halo, 0);
    r.hi[a] = std::min<std::int64_t>(cells.hi[a] + 1 + halo, n[a]);
  }
  return r;
}

Box3 owned_samples(const Box3& cells, const Index3& n) {
  Box3 s = cells;
  for (int a = 0; a < 3; ++a)
    if (cells.hi[a] == n[a] - 1) s.hi[a] = n[a];
  return s;
}

BrickReader::BrickReader(VolumeSource& source, const ExtractOptions& extract)
    : src_(source), ex_(extract), n_(source.dims) {
  // Every backend keeps the brick contract (the GL paths were checked against the CPU's brick
  // output), so bricks may run anywhere; resolve once, so all bricks run on the same one.
  ex_.backend = resolve_backend(ex_);
  layout_ = ex_.method != Method::DualContouring   ? SiteLayout::EdgeVertices
            : ex_.dc_vertices == DcVertices::Patch ? SiteLayout::PatchVertices
                                                   : SiteLayout::CellVertices;
  halo_ = extract_halo(ex_);
}

BrickPlanOptions BrickReader::plan_options(std::uint64_t memory, double max_read_amplification) {
  BrickPlanOptions po;
  po.memory = memory;
  po.max_read_amplification = max_read_amplification;
  po.halo = halo_;
  po.sample_bytes = sample_bytes();
  po.sample_buffers = read_ahead_ ? 2 : 1;
  po.slabs = src_.sequential();
  po.fixed_bytes = kept_bytes();
  po.state_bytes_per_sample = state_bytes_per_sample();
  po.volume_dims = n_;
  src_.set_overlap(2 * static_cast<std::int64_t>(halo_) + 1);
  return po;
}

VolumeView BrickReader::read(const Box3& box) {
  return read(box, buffer_);
}

VolumeView BrickReader::read(const Box3& box, std::vector<char>& buffer) {
  const std::size_t bytes =
      checked_volume_bytes(src_.type, {box.extent(0), box.extent(1), box.extent(2)});
  const auto t0 = std::chrono::steady_clock::now();
  if (buffer.size() < bytes) buffer.resize(bytes);
  src_.read(box, buffer.data());
  read_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return brick_view(src_, box, buffer.data());
}

Box3 BrickReader::count_box(const Box3& cells) const {
  const Box3 owned = owned_samples(cells, n_);
  // Patch vertices look at the cells across their faces: one sample more on every side.
  const int more = layout_ == SiteLayout::PatchVertices ? 1 : 0;
  Box3 read_box = grow(cells, more, n_);
  for (int a = 0; a < 3; ++a) read_box.hi[a] = std::min(owned.hi[a] + 1 + more, n_[a]);
  return read_box;
}

BrickCounts BrickReader::count(const Box3& cells) {
  return count(cells, read(count_box(cells)));
}

BrickCounts BrickReader::count(const Box3& cells, const VolumeView& view) const {
  const Box3 owned = owned_samples(cells, n_);
  const Box3 vbox = layout_ == SiteLayout::EdgeVertices ? owned : cells;
  check_finite(view, src_.name);
  return count_brick_sites(view, ex_.iso, layout_, vbox, cells);
}

// A sequential source keeps the planes that consecutive slabs grown by the halo share; a source
// may hold buffers of its own.
std::uint64_t BrickReader::kept_bytes() const {
  const std::uint64_t buffers = src_.buffer_bytes();
  if (!src_.sequential()) return buffers;
  return buffers + static_cast<std::uint64_t>(2 * halo_ + 1) * static_cast<std::uint64_t>(n_[0]) *
                       static_cast<std::uint64_t>(n_[1]) * scalar_size(src_.type);
}

// Macet displaces every grid vertex of its view, halo included, and keeps about 90 bytes per
// crossing for it: smooth_all()'s 58 per crossed edge and find_grid_vertices()'s 32 per displaced
// grid vertex, about one per crossing (massif at the peak of a 128^3 gzip'd volume's slices at
// --memory 2MiB: 22.5k crossed edges, 22.9k displaced grid vertices, 2.04 MB). Before a brick is
// counted, 4 bytes per sample allows for a crossing at 4.4% of the samples (engine has 3.5%,
// bonsai 2%); once it is counted, estimate() takes its real crossings where they are denser. The
// other extractors' state is per cell with output, in output_bytes_per_cell.
constexpr double kMacetBytesPerCrossing = 90;

double BrickReader::state_bytes_per_sample() const {
  return ex_.method == Method::Macet ? 4.0 : 0.0;
}

// Bytes per sample of a brick's view: the samples, and Macet's relaxed copy (doubles).
std::size_t BrickReader::sample_bytes() const {
  return scalar_size(src_.type) + (ex_.method == Method::Macet && ex_.macet_relax > 0 ? 8 : 0);
}

std::uint64_t BrickReader::estimate(const Box3& cells, std::uint64_t vertices, std::uint64_t faces,
                                    double extra_per_face) const {
  const Box3 r = grow(cells, halo_, n_);
  const double samples = static_cast<double>(r.extent(0)) * static_cast<double>(r.extent(1)) *
                         static_cast<double>(r.extent(2));
  const double per_vertex = (ex_.normals ? 24.0 : 12.0) + 8 + 8 + (ex_.normals ? 24 : 12);
  const double per_face = kFaceRecordBytes + 4 * 8 + extra_per_face;
  const double sample_buffers = read_ahead_ ? 2 : 1;
  double state = samples * state_bytes_per_sample();
  if (ex_.method == Method::Macet) {
    // Macet's crossings: the brick's own vertices, and its halo's at the same density.
    const double own = static_cast<double>(cells.extent(0)) * static_cast<double>(cells.extent(1)) *
                       static_cast<double>(cells.extent(2));
    state = std::max(state, static_cast<double>(vertices) * samples / std::max(own, 1.0) *
                                kMacetBytesPerCrossing);
  }
  return static_cast<std::uint64_t>(
      samples * (static_cast<double>(sample_bytes()) * sample_buffers + 0.125) + state +
      static_cast<double>(vertices) * per_vertex * 1.25 + static_cast<double>(faces) * per_face +
      static_cast<double>(kept_bytes()));
}

Box3 z_slice(const Box3& cells, std::int64_t s, std::int64_t count) {
  Box3 part = cells;
  part.lo[2] = cells.lo[2] + cells.extent(2) * s / count;
  part.hi[2] = cells.lo[2] + cells.extent(2) * (s + 1) / count;
  return part;
}

BrickReader::Slicing BrickReader::slice(const Box3& cells, std::uint64_t vertices,
                                        const std::vector<std::uint64_t>& plane_faces,
                                        std::uint64_t memory, double extra_per_face,
                                        bool odd) const {
  // Thinner slices carry relatively more halo, so the count grows until the largest slice fits,
  // or every slice is one cell thick. Slices run in ascending z, so a sequential source (gzip'd
  // slabs) reads them as it reads thinner slabs. Each slice is estimated with the faces its
  // planes hold: taken as an even share, a brick of bonsai tiled 4x4 cut in three at --memory
  // 64MiB gave one slice 59.6k faces of the 49.4k planned, 1.37 times its estimate.
  const std::int64_t depth = cells.extent(2);
  if (static_cast<std::int64_t>(plane_faces.size()) != depth)
    throw Error("BrickReader::slice: " + std::to_string(plane_faces.size()) +
                " plane counts for a brick " + std::to_string(depth) + " cells deep");
  std::vector<std::uint64_t> below(plane_faces.size() + 1, 0);  // faces below each plane
  for (std::size_t z = 0; z < plane_faces.size(); ++z) below[z + 1] = below[z] + plane_faces[z];
  const std::uint64_t faces = below.back();
  auto largest = [&](std::int64_t slices) {
    std::uint64_t most = 0;
    for (std::int64_t i = 0; i < slices; ++i) {
      const Box3 part = z_slice(cells, i, slices);
      const std::uint64_t f = below[static_cast<std::size_t>(part.hi[2] - cells.lo[2])] -
                              below[static_cast<std::size_t>(part.lo[2] - cells.lo[2])];
      const auto v = faces == 0 ? 0
                                : static_cast<std::uint64_t>(std::ceil(
                                      static_cast<double>(vertices) * static_cast<double>(f) /
                                      static_cast<double>(faces)));
      most = std::max(most, estimate(part, v, f, extra_per_face));
    }
    return most;
  };
  Slicing s{1, estimate(cells, vertices, faces, extra_per_face)};
  if (s.bytes <= memory) return s;
  s.count =
      std::min<std::int64_t>(depth, static_cast<std::int64_t>((s.bytes + memory - 1) / memory));
  for (;;) {
    // An even count would cut at the brick's middle plane (see tiled_simplify.cpp).
    if (odd && s.count % 2 == 0 && s.count < depth) ++s.count;
    s.bytes = largest(s.count);
    if (s.bytes <= memory) return s;
    if (s.count >= depth) break;
    ++s.count;
  }
  // The budget cannot be kept. Thin slices need fewer bytes of output each, but each re-reads
  // the halo: with Macet max's (138 samples) a brick of 10 cells cut into 10 slices took 10 times
  // as long for a need barely below the whole brick's, and with a deep halo one-cell slices can
  // need more than thicker ones. The least is the minimum over every slicing; where it is at
  // least twice the budget (no hard limit the user counted on holds anyway), the fewest slices
  // within a quarter above it; nearer the budget, the fewest that need no more than it.
  std::vector<Slicing> fewer;  // every slicing thicker than one cell, fewest slices first
  s.least = s.bytes;           // one-cell slices'
  for (std::int64_t count = 1; count < depth; ++count)
    if (!odd || count % 2 == 1) {
      fewer.push_back({count, largest(count)});
      s.least = std::min(s.least, fewer.back().bytes);
    }
  const double allowed = static_cast<double>(s.least) * (s.least >= 2 * memory ? 1.25 : 1.0);
  for (const Slicing& f : fewer)
    if (static_cast<double>(f.bytes) <= allowed) return {f.count, f.bytes, s.least};
  return s;
}

std::vector<BrickReader::Slicing> slice_bricks(
    std::int64_t bricks, const std::function<BrickReader::Slicing(std::int64_t)>& slice_brick,
    std::uint64_t memory, const Warn& warn) {
  std::vector<BrickReader::Slicing> cuts;
  cuts.reserve(static_cast<std::size_t>(bricks));
  std::uint64_t need = 0, used = 0;
  for (std::int64_t b = 0; b < bricks; ++b) {
    cuts.push_back(slice_brick(b));
    if (cuts.back().bytes > memory) {
      need = std::max(need, cuts.back().least);
      used = std::max(used, cuts.back().bytes);
    }
  }
  if (need > 0)
    say_warning(
        warn, "the memory budget of " + std::to_string(memory) +
                  " bytes is too small for this surface: the z-slices of its densest brick need at "
                  "least " +
                  std::to_string(need) +
                  " bytes (their samples with the halo and their counted output); " +
                  "the run goes over the budget, with slices of up to " + std::to_string(used) +
                  " bytes");
  return cuts;
}

void QualityAccumulator::add(double q) {
  ++triangles_;
  if (degenerate_ratio(q)) ++degenerate_;
  min_ = std::min(min_, q);
  max_ = std::max(max_, q);
  sum_.add(q);
  const int n = static_cast<int>(bins_.size());
  ++bins_[std::min(n - 1, static_cast<int>(q * n))];
  ++histogram_[histogram_bin(q)];
}

// Lower-tail quantile p, at the upper edge of the bin that reaches it.
double QualityAccumulator::quantile(double p) const {
  const auto need = static_cast<std::uint64_t>(std::ceil(p * static_cast<double>(triangles_)));
  const int n = static_cast<int>(bins_.size());
  std::uint64_t seen = 0;
  for (int i = 0; i < n; ++i) {
    seen += bins_[i];
    if (seen >= std::max<std::uint64_t>(need, 1))
      return std::min(max_, static_cast<double>(i + 1) / n);
  }
  return max_;
}

QualityStats QualityAccumulator::stats() const {
  QualityStats s;
  s.triangles = triangles_;
  s.degenerate = degenerate_;
  if (triangles_ == 0) return s;
  s.min = min_;
  s.max = max_;
  s.mean = sum_.value() / static_cast<double>(triangles_);
  s.q001 = quantile(0.001);
  s.q01 = quantile(0.01);
  s.median = quantile(0.5);
  s.histogram = histogram_;
  return s;
}

std::vector<std::uint64_t> QualityAccumulator::counters() const {
  std::vector<std::uint64_t> c{triangles_,    degenerate_,           sum_.lo & 0xffffffffu,
                               sum_.lo >> 32, sum_.hi & 0xffffffffu, sum_.hi >> 32};
  c.insert(c.end(), histogram_.begin(), histogram_.end());
  c.insert(c.end(), bins_.begin(), bins_.end());
  return c;
}

std::uint64_t QualityAccumulator::min_bits() const {
  return std::bit_cast<std::uint64_t>(min_);
}

std::uint64_t QualityAccumulator::max_bits() const {
  return std::bit_cast<std::uint64_t>(max_);
}

QualityAccumulator QualityAccumulator::from_parts(const std::vector<std::uint64_t>& c,
                                                  std::uint64_t min_bits, std::uint64_t max_bits) {
  QualityAccumulator a;
  a.triangles_ = c[0];
  a.degenerate_ = c[1];
  // Each limb is a sum of 32-bit values over the processes: carry what overflowed 32 bits.
  std::uint64_t limb[4];
  std::uint64_t carry = 0;
  for (int i = 0; i < 4; ++i) {
    const std::uint64_t v = c[2 + static_cast<std::size_t>(i)];
    const std::uint64_t low = (v & 0xffffffffu) + (carry & 0xffffffffu);
    limb[i] = low & 0xffffffffu;
    carry = (v >> 32) + (carry >> 32) + (low >> 32);
  }
  a.sum_.lo = limb[0] | (limb[1] << 32);
  a.sum_.hi = limb[2] | (limb[3] << 32);
  a.min_ = std::bit_cast<double>(min_bits);
  a.max_ = std::bit_cast<double>(max_bits);
  std::copy(c.begin() + 6, c.begin() + 26, a.histogram_.begin());
  std::copy(c.begin() + 26, c.end(), a.bins_.begin());
  return a;
}

}  // namespace isotile
