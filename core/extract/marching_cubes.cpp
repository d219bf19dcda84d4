#include "core/extract/marching_cubes.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/inside_bits.h"
#include "core/extract/marching_cubes_tables.h"
#include "core/extract/mesh_arrays.h"
#include "core/extract/scratch_vector.h"

namespace isotile {

namespace {

using namespace detail;
using std::int64_t;
using std::uint32_t;
using std::uint64_t;

// The crossed edges of one row of grid points: the edge from (i, j, k) to (i+1, j, k),
// (i, j+1, k) and (i, j, k+1) is owned by point (i, j, k). Vertices are numbered in key order, by
// point and then axis, so a vertex's rank in the row is the number of crossed edges of earlier
// points plus those of lower axes at its own point. `masks` holds the crossed edges per axis, per
// 64 points (as edge_masks() below gives them); `point` holds, for each point with a crossed edge,
// the rank of its first one (times 4) and its x and y bits: the triangles look each edge up once
// per cell around it (about four times), and one load replaces edge_rank()'s three masked
// popcounts (the whole extraction, one thread, fastest of 120 runs: bonsai 28.3 -> 25.9 ms,
// gyroid 256^3 50.4 -> 47.7 ms).
struct RowEdges {
  std::vector<std::array<uint64_t, 3>> masks;
  std::vector<uint64_t> point;  // stale where a point has no crossed edge; 64 bits: no size limit

  explicit RowEdges(int64_t n_words)
      : masks(static_cast<size_t>(n_words)), point(static_cast<size_t>(n_words) * 64) {}

  // Rank of the edge of axis a at x index i among this row's vertices.
  uint32_t local_index(int a, int64_t i) const {
    const uint64_t p = point[static_cast<size_t>(i)];
    return static_cast<uint32_t>(p >> 2) +
           static_cast<uint32_t>(std::popcount(p & ((uint64_t{1} << a) - 1)));
  }
};

// The crossed edges owned by points x in [x0, x1] of row (j, k) whose far end is in the grid.
template <class Out>
void edge_masks(const BitGrid& g, int64_t j, int64_t k, int64_t x0, int64_t x1, Out&& out) {
  const uint64_t* a = g.row(j, k);
  const uint64_t* b = j + 1 < g.ny ? g.row(j + 1, k) : nullptr;
  const uint64_t* c = k + 1 < g.nz ? g.row(j, k + 1) : nullptr;
  const int64_t w0 = x0 >> 6, w1 = x1 >> 6;
  for (int64_t w = w0; w <= w1; ++w) {
    const uint64_t in = range_bits(w, x0, x1 + 1);
    const uint64_t mx = (a[w] ^ shifted(a, w, g.words)) & in & valid_bits(w, g.nx - 1);
    const uint64_t my = b ? (a[w] ^ b[w]) & in : 0;
    const uint64_t mz = c ? (a[w] ^ c[w]) & in : 0;
    out(w, mx, my, mz);
  }
}

void row_edges(const BitGrid& g, int64_t j, int64_t k, int64_t x0, int64_t x1, RowEdges& out) {
  uint32_t total = 0;
  edge_masks(g, j, k, x0, x1, [&](int64_t w, uint64_t mx, uint64_t my, uint64_t mz) {
    out.masks[w] = {mx, my, mz};
    uint64_t* point = out.point.data() + w * 64;
    for (uint64_t m = mx | my | mz; m; m &= m - 1) {
      const int b = std::countr_zero(m);
      const uint32_t x = static_cast<uint32_t>((mx >> b) & 1),
                     y = static_cast<uint32_t>((my >> b) & 1);
      point[b] = uint64_t{total} << 2 | x | y << 1;
      total += x + y + static_cast<uint32_t>((mz >> b) & 1);
    }
  });
}

// Number of crossed edges owned by the row; the count pass needs nothing more.
uint32_t row_edge_count(const BitGrid& g, int64_t j, int64_t k, int64_t x0, int64_t x1) {
  uint32_t n = 0;
  edge_masks(g, j, k, x0, x1, [&](int64_t, uint64_t mx, uint64_t my, uint64_t mz) {
    n += static_cast<uint32_t>(std::popcount(mx) + std::popcount(my) + std::popcount(mz));
  });
  return n;
}

template <class T>
class Extractor {
 public:
  Extractor(const VolumeView& view, const MarchingCubesOptions& options)
      : view_(view), options_(options), data_(view.typed<T>()) {
    grid_.nx = view.dims[0];
    grid_.ny = view.dims[1];
    grid_.nz = view.dims[2];
    grid_.words = (grid_.nx + 63) / 64;
    cells_ = local_cell_box(view, options.cells, marching_cubes_halo(options));
    // The points whose gradient() takes a central difference along every axis.
    for (int a = 0; a < 3; ++a) {
      inner_.lo[a] = std::max<int64_t>(1, 1 - view.box.lo[a]);
      inner_.hi[a] = std::min(view.dims[a] - 1, view.global_dims[a] - 1 - view.box.lo[a]);
      if (!(view.spacing[a] > 0)) inner_.hi[a] = inner_.lo[a];  // gradient() says 0 there
    }
  }

  // With `keys`, fills only the vertices' keys (the mesh stays empty).
  Mesh run(std::vector<uint64_t>* keys = nullptr) {
    Mesh mesh;
    if (cells_.empty()) return mesh;
    // Point rows [lo, hi] in y and z carry the vertices; cell rows [lo, hi) the triangles. Row r
    // is point row (lo.y + r % ny, lo.z + r / ny).
    const int64_t ny = cells_.extent(1) + 1, rows = ny * (cells_.extent(2) + 1);
    const int64_t x0 = cells_.lo[0], x1 = cells_.hi[0];
    // Progress: the classification's and the count's rows, then the fill's, a z-slice at a time.
    Progress* const progress = options_.progress;
    progress_begin(progress, Stage::Count, grid_.ny * grid_.nz + rows);

    grid_.bits.resize(static_cast<size_t>(grid_.ny * grid_.nz * grid_.words));
    classify<T>(view_, options_.iso, grid_, progress);

    // Count.
    ScratchVector<uint32_t> vertex_count(rows), triangle_count(rows);
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows),
                      for_units(progress, ny, [&](const auto& range) {
                        for (int64_t r = range.begin(); r != range.end(); ++r) {
                          const int64_t j = cells_.lo[1] + r % ny, k = cells_.lo[2] + r / ny;
                          vertex_count[r] = row_edge_count(grid_, j, k, x0, x1);
                          triangle_count[r] = has_cells(j, k) ? count_triangles(j, k) : 0;
                        }
                      }));

    // Scan.
    ScratchVector<uint64_t> vertex_offset(rows + 1), triangle_offset(rows + 1);
    vertex_offset[0] = triangle_offset[0] = 0;
    for (int64_t r = 0; r < rows; ++r) {
      vertex_offset[r + 1] = vertex_offset[r] + vertex_count[r];
      triangle_offset[r + 1] = triangle_offset[r] + triangle_count[r];
    }
    const uint64_t n_vertices = vertex_offset[rows], n_triangles = triangle_offset[rows];
    if (n_vertices > std::numeric_limits<uint32_t>::max())
      throw CapacityError("the mesh would have " + std::to_string(n_vertices) +
                          " vertices, more than an in-memory mesh can index (2^32 - 1)");
    progress_begin(progress, Stage::Extract, rows);
    if (keys) {
      keys->resize(n_vertices);
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows),
                        for_units(progress, ny, [&](const auto& range) {
                          for (int64_t r = range.begin(); r != range.end(); ++r) {
                            const int64_t j = cells_.lo[1] + r % ny, k = cells_.lo[2] + r / ny;
                            fill_keys(j, k, keys->data() + vertex_offset[r]);
                          }
                        }));
      return mesh;
    }
    size_mesh_arrays(mesh, n_vertices, n_triangles, options_.normals);

    // Fill. Consecutive cell rows share two point rows, so the masks of rows (j+1, k) and
    // (j+1, k+1) computed for one cell row are reused as (j, k) and (j, k+1) for the next.
    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, rows), for_units(progress, ny, [&](const auto& range) {
          RowEdges store[4] = {RowEdges(grid_.words), RowEdges(grid_.words), RowEdges(grid_.words),
                               RowEdges(grid_.words)};
          // Point rows (j,k), (j+1,k), (j,k+1), (j+1,k+1), swapped by pointer.
          RowEdges* e[4] = {&store[0], &store[1], &store[2], &store[3]};
          int64_t upper_rows_of = -1;  // the row whose e[1], e[3] were computed last
          for (int64_t r = range.begin(); r != range.end(); ++r) {
            const int64_t j = cells_.lo[1] + r % ny, k = cells_.lo[2] + r / ny;
            // A sample row of plane k + 1 is first read here, at the crossings only, as the +z ends
            // of plane k's edges: a sparse walk the hardware prefetcher does not follow, so that
            // row is fetched a few rows ahead (gyroid-256, float samples: this loop 22.5 -> 13.9
            // ms). (2 to 8 rows ahead gave the same times. A prefetch never faults.)
            // With normals, the gradient at a +z end reads plane k + 2 the same way: fetched
            // too (gyroid-256, float samples: half the time of the normals went to that load).
            if (const int64_t ahead = r + 4; ahead < rows) {
              const int64_t ka = cells_.lo[2] + ahead / ny + 1;
              const int64_t planes = options_.normals ? 2 : 1;
              for (int64_t kp = ka; kp < ka + planes && kp < view_.dims[2]; ++kp) {
                const char* row = reinterpret_cast<const char*>(
                    data_ + view_.offset(x0, cells_.lo[1] + ahead % ny, kp));
                const size_t bytes = static_cast<size_t>(x1 - x0 + 1) * sizeof(T);
                for (size_t b = 0; b < bytes; b += 64) __builtin_prefetch(row + b);
              }
            }
            const bool reuse = upper_rows_of == r - 1 && j > cells_.lo[1];
            if (reuse) {
              std::swap(e[0], e[1]);
              std::swap(e[2], e[3]);
            } else {
              row_edges(grid_, j, k, x0, x1, *e[0]);
            }
            fill_vertices(j, k, *e[0], static_cast<uint32_t>(vertex_offset[r]), mesh);
            upper_rows_of = -1;
            if (triangle_count[r] == 0) continue;
            if (!reuse) row_edges(grid_, j, k + 1, x0, x1, *e[2]);
            row_edges(grid_, j + 1, k, x0, x1, *e[1]);
            row_edges(grid_, j + 1, k + 1, x0, x1, *e[3]);
            upper_rows_of = r;
            const uint32_t base[4] = {static_cast<uint32_t>(vertex_offset[r]),
                                      static_cast<uint32_t>(vertex_offset[r + 1]),
                                      static_cast<uint32_t>(vertex_offset[r + ny]),
                                      static_cast<uint32_t>(vertex_offset[r + ny + 1])};
            const RowEdges* edges[4] = {e[0], e[1], e[2], e[3]};
            fill_triangles(j, k, edges, base, mesh.triangles.data() + triangle_offset[r]);
          }
        }));
    return mesh;
  }

 private:
  bool has_cells(int64_t j, int64_t k) const { return j < cells_.hi[1] && k < cells_.hi[2]; }

  // The four point rows around cell row (j, k).
  void cell_rows(int64_t j, int64_t k, const uint64_t* rows[4]) const {
    rows[0] = grid_.row(j, k);
    rows[1] = grid_.row(j + 1, k);
    rows[2] = grid_.row(j, k + 1);
    rows[3] = grid_.row(j + 1, k + 1);
  }

  // Mixed cells of one word of cell row (j, k), restricted to the cell box.
  uint64_t mixed_cells(const CellWord& cw, int64_t w) const {
    return cw.mixed & range_bits(w, cells_.lo[0], cells_.hi[0]);
  }

  uint32_t count_triangles(int64_t j, int64_t k) const {
    const uint64_t* rows[4];
    cell_rows(j, k, rows);
    uint32_t n = 0;
    for (int64_t w = cells_.lo[0] >> 6; w <= (cells_.hi[0] - 1) >> 6; ++w) {
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      for (uint64_t m = mixed_cells(cw, w); m; m &= m - 1)
        n += mc::kCaseTable.triangle_count[cw.cell_case(std::countr_zero(m))];
    }
    return n;
  }

  double sample(int64_t i, int64_t j, int64_t k) const {
    return static_cast<double>(data_[view_.offset(i, j, k)]);
  }

  // Central differences, one-sided only at the border of the whole volume (never at a brick's
  // border, so that bricks agree); in world units.
  std::array<double, 3> gradient(int64_t i, int64_t j, int64_t k) const {
    const int64_t p[3] = {i, j, k};
    std::array<double, 3> g{};
    // Most points have both neighbours along every axis: the same differences over the same
    // 2 x spacing, without the border's index arithmetic (normals are a third of MC's time).
    if (p[0] >= inner_.lo[0] && p[0] < inner_.hi[0] && p[1] >= inner_.lo[1] &&
        p[1] < inner_.hi[1] && p[2] >= inner_.lo[2] && p[2] < inner_.hi[2]) {
      const T* c = data_ + view_.offset(i, j, k);
      for (int a = 0; a < 3; ++a)
        g[a] =
            (static_cast<double>(c[view_.strides[a]]) - static_cast<double>(c[-view_.strides[a]])) /
            (2.0 * view_.spacing[a]);
      return g;
    }
    for (int a = 0; a < 3; ++a) {
      const int64_t global = view_.box.lo[a] + p[a];
      int64_t lo[3] = {i, j, k}, hi[3] = {i, j, k};
      // The view's own border is only reached when the caller extracts every cell of a view
      // that is part of a larger volume (no halo); brick mode checks the halo up front.
      if (global > 0 && p[a] > 0) lo[a] = p[a] - 1;
      if (global + 1 < view_.global_dims[a] && p[a] + 1 < view_.dims[a]) hi[a] = p[a] + 1;
      const double h = static_cast<double>(hi[a] - lo[a]) * view_.spacing[a];
      g[a] = h > 0 ? (sample(hi[0], hi[1], hi[2]) - sample(lo[0], lo[1], lo[2])) / h : 0.0;
    }
    return g;
  }

  void fill_vertices(int64_t j, int64_t k, const RowEdges& e, uint32_t base, Mesh& mesh) const {
    const double iso = options_.iso;
    uint32_t index = base;
    for (int64_t w = cells_.lo[0] >> 6; w <= cells_.hi[0] >> 6; ++w) {
      const auto& mask = e.masks[static_cast<size_t>(w)];
      for (uint64_t m = mask[0] | mask[1] | mask[2]; m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t i = w * 64 + b;
        for (int a = 0; a < 3; ++a) {
          if (!((mask[a] >> b) & 1)) continue;
          int64_t p1[3] = {i, j, k};
          ++p1[a];
          const double v0 = sample(i, j, k), v1 = sample(p1[0], p1[1], p1[2]);
          const double t = (iso - v0) / (v1 - v0);
          const int64_t p0[3] = {i, j, k};
          Vec3f& pos = mesh.positions[index];
          for (int c = 0; c < 3; ++c) {
            double g = static_cast<double>(view_.box.lo[c] + p0[c]);
            if (c == a) g += t;
            pos[c] = static_cast<float>(view_.origin[c] + view_.spacing[c] * g);
          }
          if (options_.normals) {
            const auto g0 = gradient(i, j, k), g1 = gradient(p1[0], p1[1], p1[2]);
            double n[3], len2 = 0;
            for (int c = 0; c < 3; ++c) {
              n[c] = -(g0[c] + t * (g1[c] - g0[c]));
              len2 += n[c] * n[c];
            }
            const double inv = len2 > 0 ? 1.0 / std::sqrt(len2) : 0.0;
            for (int c = 0; c < 3; ++c) mesh.normals[index][c] = static_cast<float>(n[c] * inv);
          }
          ++index;
        }
      }
    }
  }

  // The keys need the masks only: straight from edge_masks(), no ranks.
  void fill_keys(int64_t j, int64_t k, uint64_t* out) const {
    const Index3& n = view_.global_dims;
    const uint64_t row = static_cast<uint64_t>(
        n[0] * ((view_.box.lo[1] + j) + n[1] * (view_.box.lo[2] + k)) + view_.box.lo[0]);
    edge_masks(grid_, j, k, cells_.lo[0], cells_.hi[0],
               [&](int64_t w, uint64_t mx, uint64_t my, uint64_t mz) {
                 const uint64_t mask[3] = {mx, my, mz};
                 for (uint64_t m = mx | my | mz; m; m &= m - 1) {
                   const int b = std::countr_zero(m);
                   const uint64_t lin = row + static_cast<uint64_t>(w * 64 + b);
                   for (int a = 0; a < 3; ++a)
                     if ((mask[a] >> b) & 1) *out++ = lin * 3 + static_cast<uint64_t>(a);
                 }
               });
  }

  void fill_triangles(int64_t j, int64_t k, const RowEdges* const edges[4], const uint32_t base[4],
                      Tri* out) const {
    const uint64_t* rows[4];
    cell_rows(j, k, rows);
    for (int64_t w = cells_.lo[0] >> 6; w <= (cells_.hi[0] - 1) >> 6; ++w) {
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      for (uint64_t m = mixed_cells(cw, w); m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t i = w * 64 + b;
        const int cs = cw.cell_case(b);
        // Each crossed edge's vertex index once, then the triangles pick from them.
        uint32_t id[12];
        for (unsigned em = mc::kCaseTable.edge_mask[cs]; em; em &= em - 1) {
          const int e = std::countr_zero(em);
          const mc::EdgeHome h = mc::kEdgeHome[e];
          id[e] = base[h.row] + edges[h.row]->local_index(h.axis, i + h.dx);
        }
        const auto& tris = mc::kCaseTable.triangles[cs];
        const int n = mc::kCaseTable.triangle_count[cs];
        for (int t = 0; t < n; ++t)
          *out++ = {id[tris[3 * t]], id[tris[3 * t + 1]], id[tris[3 * t + 2]]};
      }
    }
  }

  const VolumeView& view_;
  const MarchingCubesOptions& options_;
  const T* data_;
  BitGrid grid_;
  Box3 cells_;  // the cells to extract, in the view's own indices
  Box3 inner_;  // points with both neighbours along every axis in the view and the volume
};

}  // namespace

int marching_cubes_halo(const MarchingCubesOptions& options) {
  return options.normals ? 2 : 1;
}

Mesh marching_cubes(const VolumeView& view, const MarchingCubesOptions& options) {
  return visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    return Extractor<T>(view, options).run();
  });
}

std::vector<std::uint64_t> marching_cubes_vertex_keys(const VolumeView& view,
                                                      const MarchingCubesOptions& options) {
  std::vector<std::uint64_t> keys;
  visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    Extractor<T>(view, options).run(&keys);
  });
  return keys;
}

}  // namespace isotile
