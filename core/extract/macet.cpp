#include "core/extract/macet.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/extract/inside_bits.h"
#include "core/extract/macet_field.h"
#include "core/extract/macet_relax.h"
#include "core/extract/macet_search.h"
#include "core/extract/macet_table.h"
#include "core/extract/marching_cubes_tables.h"
#include "core/extract/mesh_arrays.h"

namespace isotile {

namespace {

using namespace detail;
using std::int64_t;
using std::uint32_t;
using std::uint64_t;

template <class T>
class Extractor {
 public:
  Extractor(const VolumeView& view, const MacetOptions& options)
      : view_(view),
        options_(options),
        field_(view, options.iso),
        table_(macet_case_table(true)),
        progress_(options.progress) {
    grid_.nx = view.dims[0];
    grid_.ny = view.dims[1];
    grid_.nz = view.dims[2];
    grid_.words = (grid_.nx + 63) / 64;
    cells_ = local_cell_box(view, options.cells, macet_halo(options));
  }

  Mesh run() {
    Mesh mesh;
    if (cells_.empty()) return mesh;
    // Progress, in rows of the view (a z-slice at a time): Count is the classification and the
    // two passes finding the grid vertices; Extract the push, the smoothing's four passes (its
    // umbrella sums by z-slab) and the emission's one or two; Max's search reports its own stage
    // in between (macet_search.h), so Extract begins again after it.
    const int64_t view_rows = grid_.ny * grid_.nz;
    const int64_t emit_rows = (cells_.extent(1) + 1) * (cells_.extent(2) + 1);
    const bool whole = cells_.lo == Index3{0, 0, 0} &&
                       cells_.hi == Index3{grid_.nx - 1, grid_.ny - 1, grid_.nz - 1};
    progress_begin(progress_, Stage::Count, 3 * view_rows);
    grid_.bits.resize(static_cast<size_t>(grid_.ny * grid_.nz * grid_.words));
    classify<T>(view_, options_.iso, grid_, progress_);
    // Smoothing and Max's search read the displacements around each vertex, so every grid vertex
    // of the view is displaced; the halo keeps the view small in brick mode.
    find_grid_vertices(Box3{{0, 0, 0}, view_.dims});
    const bool max = options_.quality == MacetQuality::Max && options_.max_sweeps > 0;
    const int64_t emit_units = (whole ? 1 : 2) * emit_rows;
    progress_begin(progress_, Stage::Extract,
                   4 * view_rows + std::max<int64_t>(grid_.nz - 1, 0) + (max ? 0 : emit_units));
    push_all();
    smooth_all();
    if (max) {
      macet_local_search(field_, grid_, gv_, table_, options_.max_sweeps, progress_);
      progress_begin(progress_, Stage::Extract, emit_units);
    }
    emit(mesh);
    return mesh;
  }

 private:
  // Touched samples of word w of row (j, k): those with a neighbour on the other side.
  uint64_t touched_word(int64_t j, int64_t k, int64_t w) const {
    const uint64_t* a = grid_.row(j, k);
    const uint64_t self = a[w];
    const uint64_t right = shifted(a, w, grid_.words);                 // bit i: sample i + 1
    const uint64_t left = (self << 1) | (w > 0 ? a[w - 1] >> 63 : 0);  // bit i: sample i - 1
    uint64_t t = ((self ^ right) & valid_bits(w, grid_.nx - 1)) |
                 ((self ^ left) & ~(w == 0 ? uint64_t{1} : 0));
    if (j > 0) t |= self ^ grid_.row(j - 1, k)[w];
    if (j + 1 < grid_.ny) t |= self ^ grid_.row(j + 1, k)[w];
    if (k > 0) t |= self ^ grid_.row(j, k - 1)[w];
    if (k + 1 < grid_.nz) t |= self ^ grid_.row(j, k + 1)[w];
    return t & valid_bits(w, grid_.nx);
  }

  void find_grid_vertices(const Box3& vbox) {
    gv_.box = vbox;
    gv_.words = grid_.words;
    gv_.ny = vbox.extent(1);
    const int64_t rows = vbox.extent(1) * vbox.extent(2), words = gv_.words;
    // Every word is written below (range_bits clears those outside the box).
    gv_.bits.resize(static_cast<size_t>(rows * words));
    gv_.prefix.resize(static_cast<size_t>(rows * words));
    ScratchVector<uint64_t> count(static_cast<size_t>(rows) + 1);
    count[0] = 0;
    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, rows), for_units(progress_, gv_.ny, [&](const auto& range) {
          for (int64_t r = range.begin(); r != range.end(); ++r) {
            const int64_t j = vbox.lo[1] + r % gv_.ny, k = vbox.lo[2] + r / gv_.ny;
            uint64_t n = 0;
            for (int64_t w = 0; w < words; ++w) {
              const uint64_t m = touched_word(j, k, w) & range_bits(w, vbox.lo[0], vbox.hi[0]);
              gv_.bits[static_cast<size_t>(r * words + w)] = m;
              n += static_cast<uint64_t>(std::popcount(m));
            }
            count[static_cast<size_t>(r) + 1] = n;
          }
        }));
    for (int64_t r = 0; r < rows; ++r) count[r + 1] += count[r];
    if (count[rows] > std::numeric_limits<uint32_t>::max())
      throw CapacityError("too many grid vertices for an in-memory mesh");
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows),
                      for_units(progress_, gv_.ny, [&](const auto& range) {
                        for (int64_t r = range.begin(); r != range.end(); ++r) {
                          uint32_t p = static_cast<uint32_t>(count[r]);
                          for (int64_t w = 0; w < words; ++w) {
                            gv_.prefix[static_cast<size_t>(r * words + w)] = p;
                            p += static_cast<uint32_t>(
                                std::popcount(gv_.bits[static_cast<size_t>(r * words + w)]));
                          }
                        }
                      }));
    // Every entry is written by push_all before anything reads it.
    gv_.disp.resize(count[rows]);
    gv_.value.resize(count[rows]);
  }

  // Accepts the move of grid vertex (i, j, k) from `from` by `step` (halving the step while it
  // fails): the moved vertex keeps its side and |f - iso| >= guard * |sample - iso|.
  bool try_move(int64_t i, int64_t j, int64_t k, const P3& from, P3 step, double guard, P3& disp,
                double& value) const {
    const double f = field_.sample(i, j, k) - field_.iso;
    const bool in = f >= 0;
    const P3 v = field_.global(i, j, k);
    const int64_t vi[3] = {i, j, k};
    for (int h = 0; h <= kMacetHalvings; ++h) {
      const P3 q = field_.displaced(vi, {from[0] + step[0], from[1] + step[1], from[2] + step[2]});
      const double val = field_.value(q);
      if ((val >= 0) == in && std::abs(val) >= guard * std::abs(f)) {
        for (int a = 0; a < 3; ++a) disp[a] = q[a] - v[a];
        value = val;
        return true;
      }
      for (double& c : step) c *= 0.5;
    }
    return false;
  }

  // Step 1 for the grid vertex at (i, j, k); see kMacetReach (macet_field.h).
  void push(int64_t i, int64_t j, int64_t k, P3& disp, double& value) const {
    const T* c = field_.data + view_.offset(i, j, k);
    const int64_t s[3] = {i, j, k};
    const double f = static_cast<double>(*c) - field_.iso;
    const bool in = f >= 0;
    P3 d{0, 0, 0};
    for (int a = 0; a < 3; ++a)
      for (int dir = -1; dir <= 1; dir += 2) {
        if (s[a] + dir < 0 || s[a] + dir >= view_.dims[a]) continue;
        const double g = static_cast<double>(c[dir * view_.strides[a]]) - field_.iso;
        // Selected rather than branched on (the branches are unpredictable); subtracting a zero
        // push leaves d[a] unchanged, so the sums are those of the skipped terms.
        const double t = f / (f - g);  // the crossing, in edge lengths from this vertex
        const bool pushes = (g >= 0) != in && t < kMacetReach;
        d[a] -= dir * (pushes ? kMacetReach - t : 0.0);
      }
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (len > kMacetPushCap)
      for (double& c : d) c *= kMacetPushCap / len;
    disp = {0, 0, 0};
    value = f;
    if (len > 0) try_move(i, j, k, {0, 0, 0}, d, kMacetGuard, disp, value);
  }

  // Calls fn(i, j, k, index) for every grid vertex, rows in parallel.
  template <class F>
  void for_grid_vertices(F&& fn) const {
    const Box3& b = gv_.box;
    const int64_t rows = b.extent(1) * b.extent(2);
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows),
                      for_units(progress_, gv_.ny, [&](const auto& range) {
                        for (int64_t r = range.begin(); r != range.end(); ++r) {
                          const int64_t j = b.lo[1] + r % gv_.ny, k = b.lo[2] + r / gv_.ny;
                          for (int64_t w = b.lo[0] >> 6; w <= (b.hi[0] - 1) >> 6; ++w) {
                            const size_t word = static_cast<size_t>(r * gv_.words + w);
                            uint32_t idx = gv_.prefix[word];
                            for (uint64_t m = gv_.bits[word]; m; m &= m - 1, ++idx)
                              fn(w * 64 + std::countr_zero(m), j, k, idx);
                          }
                        }
                      }));
  }

  void push_all() {
    for_grid_vertices([&](int64_t i, int64_t j, int64_t k, uint32_t idx) {
      push(i, j, k, gv_.disp[idx], gv_.value[idx]);
    });
  }

  // The crossed edges of the whole view, ranked like the emitted ones.
  struct EdgeIndex {
    int64_t ny = 0, words = 0;
    ScratchVector<EdgeWord> bits;    // written in full by row_edges_in
    ScratchVector<uint64_t> offset;  // per point row
    uint64_t operator()(int64_t i, int64_t j, int64_t k, int a) const {
      const int64_t r = k * ny + j;
      return offset[r] + edge_rank(bits.data() + r * words, a, i);
    }
  };

  // Step 2, one Jacobi pass (new displacements from old ones only, so the order of the rows does
  // not matter). Crossings are estimated linearly between the displaced end points (their values
  // there are known), which is close enough to steer the smoothing and needs no root search.
  void smooth_all() {
    const int64_t ny = grid_.ny, nz = grid_.nz, words = grid_.words, rows = ny * nz;
    EdgeIndex& ei = edge_index_;
    ei.ny = ny;
    ei.words = words;
    ei.bits.resize(static_cast<size_t>(rows * words));
    ei.offset.resize(static_cast<size_t>(rows) + 1);
    ei.offset[0] = 0;
    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, rows), for_units(progress_, ny, [&](const auto& range) {
          for (int64_t r = range.begin(); r != range.end(); ++r) {
            uint32_t n = 0;
            row_edges_in(r % ny, r / ny, 0, grid_.nx - 1, ei.bits.data() + r * words, &n);
            ei.offset[r + 1] = n;
          }
        }));
    for (int64_t r = 0; r < rows; ++r) ei.offset[r + 1] += ei.offset[r];
    const size_t n_edges = ei.offset[rows];
    // Written in full by the next pass (sum and count included), so left uninitialised here.
    ScratchVector<P3> x(n_edges), sum(n_edges);
    ScratchVector<double> t(n_edges);
    ScratchVector<std::uint16_t> count(n_edges);
    auto for_edges = [&](auto&& fn) {
      tbb::parallel_for(
          tbb::blocked_range<int64_t>(0, rows), for_units(progress_, ny, [&](const auto& range) {
            for (int64_t r = range.begin(); r != range.end(); ++r) {
              const int64_t j = r % ny, k = r / ny;
              uint64_t idx = ei.offset[r];
              const EdgeWord* e = ei.bits.data() + r * words;
              for (int64_t w = 0; w < words; ++w)
                for (uint64_t m = e[w].mask[0] | e[w].mask[1] | e[w].mask[2]; m; m &= m - 1) {
                  const int b = std::countr_zero(m);
                  for (int a = 0; a < 3; ++a)
                    if ((e[w].mask[a] >> b) & 1) fn(w * 64 + b, j, k, a, idx++);
                }
            }
          }));
    };
    for_edges([&](int64_t i, int64_t j, int64_t k, int a, uint64_t idx) {
      int64_t q[3] = {i, j, k};
      ++q[a];
      const uint32_t i0 = gv_.index(i, j, k), i1 = gv_.index(q[0], q[1], q[2]);
      const double f0 = gv_.value[i0], f1 = gv_.value[i1];
      const int64_t s[3] = {i, j, k};
      // Linear, between the displaced end points (see above).
      t[idx] = edge_crossing(field_, grid_, s, q, P3{}, P3{}, f0, f1, true);
      for (int c = 0; c < 3; ++c) {
        const double a0 = static_cast<double>(view_.box.lo[c] + s[c]) + gv_.disp[i0][c];
        const double a1 = static_cast<double>(view_.box.lo[c] + q[c]) + gv_.disp[i1][c];
        x[idx][c] = a0 + t[idx] * (a1 - a0);
      }
      sum[idx] = {0, 0, 0};
      count[idx] = 0;
    });
    // Cell rows at the view's last y or z hold no cells.
    row_triangles_.assign(static_cast<size_t>(rows) + 1, 0);
    // Umbrella sums, cell by cell: each triangle adds its other two crossings to each of its
    // corners (so a neighbour counts once per shared triangle). Cell slabs k and k + 2 touch
    // disjoint point slabs, so the slabs of one global parity run in parallel, each slab in
    // (j, i, triangle) order: every crossing's sum is added up in the same order in any view and
    // for any thread count.
    for (int phase = 0; phase < 2; ++phase) {
      const int64_t k0 = (phase + view_.box.lo[2]) & 1;
      const int64_t slabs = nz - 1 > k0 ? (nz - 1 - k0 + 1) / 2 : 0;
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, slabs),
                        for_units(progress_, 1, [&](const auto& range) {
                          for (int64_t m = range.begin(); m != range.end(); ++m)
                            for (int64_t j = 0, k = k0 + 2 * m; j + 1 < ny; ++j)
                              row_triangles_[static_cast<size_t>(k * ny + j) + 1] =
                                  sum_cells(j, k, ei, x, sum, count);
                        }));
    }
    // Each move reads only its own displacement and the sums above: updated in place. A grid
    // vertex's crossed edges are found in the edge index's masks, ranked as edge_rank does:
    // along +x, +y, +z in row (j, k) at x = i, along -x there at i - 1, along -y in row (j - 1, k)
    // and along -z in row (j, k - 1), both at i.
    for_grid_vertices([&](int64_t i, int64_t j, int64_t k, uint32_t idx) {
      const int64_t w = i >> 6, b = i & 63, r = k * ny + j;
      const uint64_t bit = uint64_t{1} << b, below = bit - 1;
      const EdgeWord& here = ei.bits[static_cast<size_t>(r * words + w)];
      const uint64_t base = ei.offset[r] + here.prefix + std::popcount(here.mask[0] & below) +
                            std::popcount(here.mask[1] & below) +
                            std::popcount(here.mask[2] & below);
      // The crossed edges in the order their terms are added: -x, +x, -y, +y, -z, +z (odd slots:
      // edges leaving the vertex).
      uint64_t e[6];
      unsigned crossed = 0;
      if (i > 0 && ((b > 0 ? here.mask[0] << 1
                           : ei.bits[static_cast<size_t>(r * words + w - 1)].mask[0] >> 63) &
                    bit)) {
        e[0] = ei(i - 1, j, k, 0);
        crossed |= 1;
      }
      const uint64_t has_x = (here.mask[0] >> b) & 1, has_y = (here.mask[1] >> b) & 1;
      if (has_x) e[1] = base, crossed |= 2;
      if (j > 0) {
        if (ei.bits[static_cast<size_t>((r - 1) * words + w)].mask[1] & bit)
          e[2] = ei(i, j - 1, k, 1), crossed |= 4;
      }
      if (has_y) e[3] = base + has_x, crossed |= 8;
      if (k > 0) {
        if (ei.bits[static_cast<size_t>((r - ny) * words + w)].mask[2] & bit)
          e[4] = ei(i, j, k - 1, 2), crossed |= 16;
      }
      if ((here.mask[2] >> b) & 1) e[5] = base + has_x + has_y, crossed |= 32;
      P3 acc{0, 0, 0};
      double weight = 0;
      for (unsigned m = crossed; m; m &= m - 1) {
        const int slot = std::countr_zero(m);
        const uint64_t ed = e[slot];
        // How far the crossing follows this end point.
        const double wt = std::clamp(slot & 1 ? 1 - t[ed] : t[ed], 0.0, 1.0);
        const double n = count[ed];
        for (int c = 0; c < 3; ++c) acc[c] += wt * (n > 0 ? sum[ed][c] / n - x[ed][c] : 0.0);
        weight += wt;
      }
      if (weight <= 0) return;
      for (double& c : acc) c /= weight;
      const P3 g = field_.gradient(i, j, k);
      const double g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
      if (g2 > 0) {
        const double along = (acc[0] * g[0] + acc[1] * g[1] + acc[2] * g[2]) / g2;
        for (int c = 0; c < 3; ++c) acc[c] -= along * g[c];
      }
      const P3 from = gv_.disp[idx];
      P3 d{from[0] + acc[0], from[1] + acc[1], from[2] + acc[2]};
      const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      if (len > kMacetSmoothCap)
        for (double& c : d) c *= kMacetSmoothCap / len;
      try_move(i, j, k, from, {d[0] - from[0], d[1] - from[1], d[2] - from[2]}, kMacetSmoothGuard,
               gv_.disp[idx], gv_.value[idx]);
    });
  }

  // The umbrella sums of the crossings in the mixed cells of cell row (j, k) (see smooth_all).
  // Returns the cell row's triangle count.
  uint64_t sum_cells(int64_t j, int64_t k, const EdgeIndex& ei, const ScratchVector<P3>& x,
                     ScratchVector<P3>& sum, ScratchVector<std::uint16_t>& count) const {
    uint64_t triangles = 0;
    const uint64_t* rows[4] = {grid_.row(j, k), grid_.row(j + 1, k), grid_.row(j, k + 1),
                               grid_.row(j + 1, k + 1)};
    const int64_t r0 = k * ei.ny + j;
    const int64_t pr[4] = {r0, r0 + 1, r0 + ei.ny, r0 + ei.ny + 1};
    for (int64_t w = 0; w <= (grid_.nx - 2) >> 6; ++w) {
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      for (uint64_t m = cw.mixed; m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t i = w * 64 + b;
        const int cs = cw.cell_case(b);
        uint64_t id[12];
        for (unsigned em = table_.edge_mask[cs]; em; em &= em - 1) {
          const int ed = std::countr_zero(em);
          const mc::EdgeHome h = mc::kEdgeHome[ed];
          id[ed] = ei.offset[pr[h.row]] +
                   edge_rank(ei.bits.data() + pr[h.row] * ei.words, h.axis, i + h.dx);
        }
        const auto& tris = table_.triangles[cs];
        for (int t = 0; t < table_.triangle_count[cs]; ++t)
          for (int v = 0; v < 3; ++v) {
            const uint64_t self = id[tris[3 * t + v]], o1 = id[tris[3 * t + (v + 1) % 3]],
                           o2 = id[tris[3 * t + (v + 2) % 3]];
            for (int c = 0; c < 3; ++c) sum[self][c] += x[o1][c] + x[o2][c];
            count[self] += 2;
          }
        triangles += static_cast<uint64_t>(table_.triangle_count[cs]);
      }
    }
    return triangles;
  }

  // Crossed edges owned by points x in [x0, x1] of row (j, k) whose far end is in the view.
  void row_edges_in(int64_t j, int64_t k, int64_t x0, int64_t x1, EdgeWord* out,
                    uint32_t* total) const {
    const uint64_t* a = grid_.row(j, k);
    const uint64_t* b = j + 1 < grid_.ny ? grid_.row(j + 1, k) : nullptr;
    const uint64_t* c = k + 1 < grid_.nz ? grid_.row(j, k + 1) : nullptr;
    uint32_t n = 0;
    for (int64_t w = 0; w < grid_.words; ++w) {
      const uint64_t in = range_bits(w, x0, x1 + 1);
      const uint64_t mx = (a[w] ^ shifted(a, w, grid_.words)) & in & valid_bits(w, grid_.nx - 1);
      const uint64_t my = b ? (a[w] ^ b[w]) & in : 0;
      const uint64_t mz = c ? (a[w] ^ c[w]) & in : 0;
      if (out) out[w] = {{mx, my, mz}, n};
      n += static_cast<uint32_t>(std::popcount(mx) + std::popcount(my) + std::popcount(mz));
    }
    *total = n;
  }

  P3 crossing(int64_t i, int64_t j, int64_t k, int a, typename Field<T>::Corners& cache) const {
    int64_t q[3] = {i, j, k};
    ++q[a];
    const uint32_t i0 = gv_.index(i, j, k), i1 = gv_.index(q[0], q[1], q[2]);
    const P3& d0 = gv_.disp[i0];
    const P3& d1 = gv_.disp[i1];
    const double f0 = gv_.value[i0], f1 = gv_.value[i1];
    const P3 p0 = field_.global(i, j, k, d0);
    const P3 p1 = field_.global(q[0], q[1], q[2], d1);
    const bool straight = d0 == P3{0, 0, 0} && d1 == P3{0, 0, 0};
    const int64_t s[3] = {i, j, k};
    const double t = edge_crossing(field_, grid_, s, q, p0, p1, f0, f1, straight, &cache);
    return {p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1]), p0[2] + t * (p1[2] - p0[2])};
  }

  int count_triangles(int64_t j, int64_t k) const {
    const uint64_t* rows[4] = {grid_.row(j, k), grid_.row(j + 1, k), grid_.row(j, k + 1),
                               grid_.row(j + 1, k + 1)};
    int n = 0;
    for (int64_t w = cells_.lo[0] >> 6; w <= (cells_.hi[0] - 1) >> 6; ++w) {
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      for (uint64_t m = cw.mixed & range_bits(w, cells_.lo[0], cells_.hi[0]); m; m &= m - 1)
        n += table_.triangle_count[cw.cell_case(std::countr_zero(m))];
    }
    return n;
  }

  void emit(Mesh& mesh) {
    const int64_t ny = cells_.extent(1) + 1, rows = ny * (cells_.extent(2) + 1);
    const int64_t words = grid_.words;
    // With every cell of the view emitted (in core), the emitted edges, in their order, are the
    // smoothing's edge index.
    const bool whole = cells_.lo == Index3{0, 0, 0} &&
                       cells_.hi == Index3{grid_.nx - 1, grid_.ny - 1, grid_.nz - 1};
    ScratchVector<EdgeWord> own_edges;  // written in full by row_edges_in
    std::vector<uint64_t> own_offset;
    if (!whole) {
      own_edges.resize(static_cast<size_t>(rows * words));
      own_offset.assign(static_cast<size_t>(rows) + 1, 0);
    }
    const EdgeWord* edges = whole ? edge_index_.bits.data() : own_edges.data();
    const uint64_t* vertex_offset = whole ? edge_index_.offset.data() : own_offset.data();
    // The smoothing counted the triangles of every cell row too.
    std::vector<uint64_t> triangle_offset =
        whole ? std::move(row_triangles_) : std::vector<uint64_t>(static_cast<size_t>(rows) + 1, 0);
    if (!whole)
      tbb::parallel_for(
          tbb::blocked_range<int64_t>(0, rows), for_units(progress_, ny, [&](const auto& range) {
            for (int64_t r = range.begin(); r != range.end(); ++r) {
              const int64_t j = cells_.lo[1] + r % ny, k = cells_.lo[2] + r / ny;
              uint32_t n = 0;
              row_edges_in(j, k, cells_.lo[0], cells_.hi[0], own_edges.data() + r * words, &n);
              own_offset[r + 1] = n;
              if (j < cells_.hi[1] && k < cells_.hi[2])
                triangle_offset[r + 1] = count_triangles(j, k);
            }
          }));
    for (int64_t r = 0; r < rows; ++r) {
      if (!whole) own_offset[r + 1] += own_offset[r];
      triangle_offset[r + 1] += triangle_offset[r];
    }
    const uint64_t n_vertices = vertex_offset[rows], n_triangles = triangle_offset[rows];
    if (n_vertices > std::numeric_limits<uint32_t>::max())
      throw CapacityError("the mesh would have " + std::to_string(n_vertices) +
                          " vertices, more than an in-memory mesh can index (2^32 - 1)");
    size_mesh_arrays(mesh, n_vertices, n_triangles, options_.normals);

    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, rows), for_units(progress_, ny, [&](const auto& range) {
          for (int64_t r = range.begin(); r != range.end(); ++r) {
            const int64_t j = cells_.lo[1] + r % ny, k = cells_.lo[2] + r / ny;
            fill_vertices(j, k, edges + r * words, vertex_offset[r], mesh);
            if (j < cells_.hi[1] && k < cells_.hi[2]) {
              const EdgeWord* e[4] = {edges + r * words, edges + (r + 1) * words,
                                      edges + (r + ny) * words, edges + (r + ny + 1) * words};
              const uint64_t base[4] = {vertex_offset[r], vertex_offset[r + 1],
                                        vertex_offset[r + ny], vertex_offset[r + ny + 1]};
              fill_triangles(j, k, e, base, mesh.triangles.data() + triangle_offset[r]);
            }
          }
        }));
  }

  void fill_vertices(int64_t j, int64_t k, const EdgeWord* e, uint64_t index, Mesh& mesh) const {
    // Neighbouring crossings' root searches often start in the same cell.
    typename Field<T>::Corners cache;
    for (int64_t w = cells_.lo[0] >> 6; w <= cells_.hi[0] >> 6; ++w) {
      const uint64_t* mask = e[w].mask;
      for (uint64_t m = mask[0] | mask[1] | mask[2]; m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t i = w * 64 + b;
        for (int a = 0; a < 3; ++a) {
          if (!((mask[a] >> b) & 1)) continue;
          const P3 p = crossing(i, j, k, a, cache);
          Vec3f& pos = mesh.positions[index];
          for (int c = 0; c < 3; ++c)
            pos[c] = static_cast<float>(view_.origin[c] + view_.spacing[c] * p[c]);
          if (options_.normals) {
            const P3 g = field_.world_gradient(p);
            const double len = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
            const double inv = len > 0 ? -1.0 / len : 0.0;
            for (int c = 0; c < 3; ++c) mesh.normals[index][c] = static_cast<float>(g[c] * inv);
          }
          ++index;
        }
      }
    }
  }

  void fill_triangles(int64_t j, int64_t k, const EdgeWord* const e[4], const uint64_t base[4],
                      Tri* out) const {
    const uint64_t* rows[4] = {grid_.row(j, k), grid_.row(j + 1, k), grid_.row(j, k + 1),
                               grid_.row(j + 1, k + 1)};
    for (int64_t w = cells_.lo[0] >> 6; w <= (cells_.hi[0] - 1) >> 6; ++w) {
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      for (uint64_t m = cw.mixed & range_bits(w, cells_.lo[0], cells_.hi[0]); m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t i = w * 64 + b;
        const int cs = cw.cell_case(b);
        uint32_t id[12];
        for (unsigned em = table_.edge_mask[cs]; em; em &= em - 1) {
          const int ed = std::countr_zero(em);
          const mc::EdgeHome h = mc::kEdgeHome[ed];
          id[ed] = static_cast<uint32_t>(base[h.row] + edge_rank(e[h.row], h.axis, i + h.dx));
        }
        const auto& tris = table_.triangles[cs];
        for (int t = 0; t < table_.triangle_count[cs]; ++t)
          *out++ = {id[tris[3 * t]], id[tris[3 * t + 1]], id[tris[3 * t + 2]]};
      }
    }
  }

  const VolumeView& view_;
  const MacetOptions& options_;
  Field<T> field_;
  const MacetCaseTable& table_;
  BitGrid grid_;
  Box3 cells_;
  Progress* progress_;  // options_.progress
  GridVertices gv_;
  EdgeIndex edge_index_;  // the view's crossed edges, from smooth_all
  std::vector<uint64_t>
      row_triangles_;  // entry r + 1: the triangles of cell row r, from smooth_all
};

}  // namespace

int macet_halo(const MacetOptions& options) {
  check_macet_options(options);
  // An emitted edge ends at most one sample past the cells. Its end point's smoothing reads the
  // crossings of the cells around its edges (end points one sample further), whose pushes read
  // one sample more: 3. Its root search and normal stay within that. Max: the emitted end points
  // (one past the cells) depend on a chain of colour steps, each reading the displacements within
  // kGuardReach (3) of its vertex, that reaches macet_search_reach(sweeps) samples; the chain's
  // last step reads crossings whose end points lie 3 further, found by root searches within one
  // voxel of them and pushed and smoothed from samples two around them: 1 + reach + 3 + 2.
  const int relax = options.relax > 0 ? 1 : 0;
  if (options.quality == MacetQuality::Max && options.max_sweeps > 0)
    return 1 + detail::macet_search_reach(options.max_sweeps) + detail::kGuardReach + 2 + relax;
  return 3 + relax;
}

void check_macet_options(const MacetOptions& options) {
  // Each sweep widens the halo by 45 samples, and the reach is computed in time growing with the
  // square of the sweeps: INT_MAX took minutes in macet_halo() alone and overflowed it.
  constexpr int kMaxSweeps = 100;
  if (options.max_sweeps < 0 || options.max_sweeps > kMaxSweeps)
    throw InputError("macet: max_sweeps must be in [0, " + std::to_string(kMaxSweeps) + "], got " +
                     std::to_string(options.max_sweeps));
  if (!(options.relax >= 0 && options.relax < 0.5))
    throw InputError("macet: relax must lie in [0, 0.5) edge lengths, got " +
                     number_text(options.relax));
}

Mesh macet(const VolumeView& view, const MacetOptions& options) {
  check_extraction_input(view, options.iso);
  check_macet_options(options);
  if (options.relax > 0) {
    // The relaxed samples are doubles; the Field converts every sample to double anyway, so the
    // arithmetic on unrelaxed samples is unchanged.
    const ScratchVector<double> samples = relax_pinned_samples(view, options.iso, options.relax);
    VolumeView relaxed = view;
    relaxed.data = samples.data();
    relaxed.type = ScalarType::Float64;
    relaxed.strides = {1, view.dims[0], view.dims[0] * view.dims[1]};
    return Extractor<double>(relaxed, options).run();
  }
  return visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    return Extractor<T>(view, options).run();
  });
}

}  // namespace isotile
