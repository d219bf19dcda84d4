#include "core/marching_cubes.h"

#include <tbb/parallel_for.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/marching_cubes_tables.h"

namespace isotile {

namespace {

using std::int64_t;
using std::uint32_t;
using std::uint64_t;

// The classification of every sample is packed into one bit per sample, 64 to a word, one run of
// words per grid row (fixed j, k). Crossed edges and mixed cells then fall out of word-wide XORs,
// so empty space costs a few instructions per 64 cells, and a vertex's index is a rank (popcount)
// in these masks: no per-edge index array is ever stored.
struct BitGrid {
  int64_t nx = 0, ny = 0, nz = 0;
  int64_t words = 0;  // per row
  std::vector<uint64_t> bits;

  const uint64_t* row(int64_t j, int64_t k) const { return bits.data() + (k * ny + j) * words; }
};

// Samples compare as `value >= iso`. For integer types the threshold becomes the smallest inside
// integer, which gives exactly the same answer as comparing in double without the conversion.
template <class T>
struct InsideTest {
  explicit InsideTest(double iso) {
    if constexpr (std::is_integral_v<T>) {
      const double t = std::ceil(iso);
      if (t <= static_cast<double>(std::numeric_limits<T>::min())) {
        threshold = std::numeric_limits<int64_t>::min();
      } else if (t > static_cast<double>(std::numeric_limits<T>::max())) {
        threshold = std::numeric_limits<int64_t>::max();
      } else {
        threshold = static_cast<int64_t>(t);
      }
    } else {
      threshold_f = iso;
    }
  }
  bool operator()(T v) const {
    if constexpr (std::is_integral_v<T>) {
      return static_cast<int64_t>(v) >= threshold;
    } else {
      return static_cast<double>(v) >= threshold_f;
    }
  }
  int64_t threshold = 0;
  double threshold_f = 0;
};

template <class T>
void classify(const VolumeView& view, double iso, BitGrid& grid) {
  const T* data = view.typed<T>();
  const InsideTest<T> inside(iso);
  const int64_t nx = grid.nx, words = grid.words, sx = view.strides[0];
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, grid.ny * grid.nz), [&](const auto& range) {
    for (int64_t r = range.begin(); r != range.end(); ++r) {
      const int64_t j = r % grid.ny, k = r / grid.ny;
      const T* src = data + view.offset(0, j, k);
      uint64_t* dst = grid.bits.data() + r * words;
      for (int64_t w = 0; w < words; ++w) {
        const int64_t i0 = w * 64, n = std::min<int64_t>(64, nx - i0);
        uint64_t m = 0;
        if (sx == 1) {
          for (int64_t b = 0; b < n; ++b) m |= uint64_t{inside(src[i0 + b])} << b;
        } else {
          for (int64_t b = 0; b < n; ++b) m |= uint64_t{inside(src[(i0 + b) * sx])} << b;
        }
        dst[w] = m;
      }
    }
  });
}

// Masks of the crossed edges owned by one row of grid points: the edge from (i, j, k) to
// (i+1, j, k), (i, j+1, k) and (i, j, k+1) is owned by point (i, j, k). `prefix[a][w]` counts the
// crossed edges of axis a before word w, so the rank of any edge is prefix + popcount of a word.
struct RowEdges {
  std::vector<uint64_t> mask[3];
  std::vector<uint32_t> prefix[3];
  uint32_t count[3] = {0, 0, 0};

  explicit RowEdges(int64_t words) {
    for (int a = 0; a < 3; ++a) {
      mask[a].resize(words);
      prefix[a].resize(words);
    }
  }

  // Rank of the edge of axis a at x index i among this row's vertices.
  uint32_t local_index(int a, int64_t i) const {
    const uint32_t base = a == 0 ? 0 : (a == 1 ? count[0] : count[0] + count[1]);
    const uint64_t below = mask[a][i >> 6] & ((uint64_t{1} << (i & 63)) - 1);
    return base + prefix[a][i >> 6] + static_cast<uint32_t>(std::popcount(below));
  }
};

// Words of bit i+1 aligned to bit i ("the sample to the right").
inline uint64_t shifted(const uint64_t* row, int64_t w, int64_t words) {
  const uint64_t hi = w + 1 < words ? row[w + 1] << 63 : 0;
  return (row[w] >> 1) | hi;
}

// Bits [0, n) set for word w of a row holding n meaningful bits.
inline uint64_t valid_bits(int64_t w, int64_t n) {
  const int64_t left = n - w * 64;
  if (left >= 64) return ~uint64_t{0};
  if (left <= 0) return 0;
  return (uint64_t{1} << left) - 1;
}

void row_edges(const BitGrid& g, int64_t j, int64_t k, RowEdges& out) {
  const uint64_t* a = g.row(j, k);
  const uint64_t* b = j + 1 < g.ny ? g.row(j + 1, k) : nullptr;
  const uint64_t* c = k + 1 < g.nz ? g.row(j, k + 1) : nullptr;
  uint32_t total[3] = {0, 0, 0};
  for (int64_t w = 0; w < g.words; ++w) {
    const uint64_t mx = (a[w] ^ shifted(a, w, g.words)) & valid_bits(w, g.nx - 1);
    const uint64_t my = b ? (a[w] ^ b[w]) & valid_bits(w, g.nx) : 0;
    const uint64_t mz = c ? (a[w] ^ c[w]) & valid_bits(w, g.nx) : 0;
    const uint64_t m[3] = {mx, my, mz};
    for (int ax = 0; ax < 3; ++ax) {
      out.mask[ax][w] = m[ax];
      out.prefix[ax][w] = total[ax];
      total[ax] += static_cast<uint32_t>(std::popcount(m[ax]));
    }
  }
  for (int ax = 0; ax < 3; ++ax) out.count[ax] = total[ax];
}

// Mixed cells of the cell row (j, k): cells whose eight corners are not all on one side.
inline uint64_t mixed_cells(const uint64_t* a, const uint64_t* b, const uint64_t* c,
                            const uint64_t* d, int64_t w, int64_t words, int64_t nx) {
  const uint64_t any = a[w] | b[w] | c[w] | d[w];
  const uint64_t all = a[w] & b[w] & c[w] & d[w];
  const uint64_t any_r = shifted(a, w, words) | shifted(b, w, words) | shifted(c, w, words) |
                         shifted(d, w, words);
  const uint64_t all_r = shifted(a, w, words) & shifted(b, w, words) & shifted(c, w, words) &
                         shifted(d, w, words);
  return (any | any_r) & ~(all & all_r) & valid_bits(w, nx - 1);
}

inline int bit(const uint64_t* row, int64_t i) { return static_cast<int>((row[i >> 6] >> (i & 63)) & 1); }

inline int cell_case(const uint64_t* a, const uint64_t* b, const uint64_t* c, const uint64_t* d,
                     int64_t i) {
  return bit(a, i) | bit(a, i + 1) << 1 | bit(b, i) << 2 | bit(b, i + 1) << 3 | bit(c, i) << 4 |
         bit(c, i + 1) << 5 | bit(d, i) << 6 | bit(d, i + 1) << 7;
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
  }

  Mesh run() {
    Mesh mesh;
    if (grid_.nx < 2 || grid_.ny < 2 || grid_.nz < 2) return mesh;
    const int64_t rows = grid_.ny * grid_.nz;
    grid_.bits.resize(static_cast<size_t>(rows * grid_.words));
    classify<T>(view_, options_.iso, grid_);

    // Count.
    std::vector<uint32_t> vertex_count(rows), triangle_count(rows);
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows), [&](const auto& range) {
      RowEdges edges(grid_.words);
      for (int64_t r = range.begin(); r != range.end(); ++r) {
        const int64_t j = r % grid_.ny, k = r / grid_.ny;
        row_edges(grid_, j, k, edges);
        vertex_count[r] = edges.count[0] + edges.count[1] + edges.count[2];
        triangle_count[r] = count_triangles(j, k);
      }
    });

    // Scan.
    std::vector<uint64_t> vertex_offset(rows + 1), triangle_offset(rows + 1);
    for (int64_t r = 0; r < rows; ++r) {
      vertex_offset[r + 1] = vertex_offset[r] + vertex_count[r];
      triangle_offset[r + 1] = triangle_offset[r] + triangle_count[r];
    }
    const uint64_t n_vertices = vertex_offset[rows], n_triangles = triangle_offset[rows];
    if (n_vertices > std::numeric_limits<uint32_t>::max())
      throw CapacityError("the mesh would have " + std::to_string(n_vertices) +
                          " vertices, more than an in-memory mesh can index (2^32 - 1)");
    mesh.positions.resize(n_vertices);
    if (options_.normals) mesh.normals.resize(n_vertices);
    mesh.triangles.resize(n_triangles);

    // Fill.
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows), [&](const auto& range) {
      RowEdges e00(grid_.words), e10(grid_.words), e01(grid_.words), e11(grid_.words);
      for (int64_t r = range.begin(); r != range.end(); ++r) {
        const int64_t j = r % grid_.ny, k = r / grid_.ny;
        row_edges(grid_, j, k, e00);
        fill_vertices(j, k, e00, static_cast<uint32_t>(vertex_offset[r]), mesh);
        if (triangle_count[r] == 0) continue;
        row_edges(grid_, j + 1, k, e10);
        row_edges(grid_, j, k + 1, e01);
        row_edges(grid_, j + 1, k + 1, e11);
        const uint32_t base[4] = {static_cast<uint32_t>(vertex_offset[r]),
                                  static_cast<uint32_t>(vertex_offset[r + 1]),
                                  static_cast<uint32_t>(vertex_offset[r + grid_.ny]),
                                  static_cast<uint32_t>(vertex_offset[r + grid_.ny + 1])};
        const RowEdges* rows4[4] = {&e00, &e10, &e01, &e11};
        fill_triangles(j, k, rows4, base, mesh.triangles.data() + triangle_offset[r]);
      }
    });
    return mesh;
  }

 private:
  uint32_t count_triangles(int64_t j, int64_t k) const {
    if (j + 1 >= grid_.ny || k + 1 >= grid_.nz) return 0;
    const uint64_t *a = grid_.row(j, k), *b = grid_.row(j + 1, k), *c = grid_.row(j, k + 1),
                   *d = grid_.row(j + 1, k + 1);
    uint32_t n = 0;
    for (int64_t w = 0; w < grid_.words; ++w) {
      for (uint64_t m = mixed_cells(a, b, c, d, w, grid_.words, grid_.nx); m; m &= m - 1) {
        const int64_t i = w * 64 + std::countr_zero(m);
        n += mc::kCaseTable.triangle_count[cell_case(a, b, c, d, i)];
      }
    }
    return n;
  }

  double sample(int64_t i, int64_t j, int64_t k) const {
    return static_cast<double>(data_[view_.offset(i, j, k)]);
  }

  // Central differences inside, one-sided at the border of the view; in world units.
  std::array<double, 3> gradient(int64_t i, int64_t j, int64_t k) const {
    const int64_t p[3] = {i, j, k};
    std::array<double, 3> g{};
    for (int a = 0; a < 3; ++a) {
      int64_t lo[3] = {i, j, k}, hi[3] = {i, j, k};
      lo[a] = std::max<int64_t>(p[a] - 1, 0);
      hi[a] = std::min<int64_t>(p[a] + 1, view_.dims[a] - 1);
      const double h = static_cast<double>(hi[a] - lo[a]) * view_.spacing[a];
      g[a] = h > 0 ? (sample(hi[0], hi[1], hi[2]) - sample(lo[0], lo[1], lo[2])) / h : 0.0;
    }
    return g;
  }

  void fill_vertices(int64_t j, int64_t k, const RowEdges& e, uint32_t base, Mesh& mesh) const {
    const double iso = options_.iso;
    uint32_t index = base;
    for (int a = 0; a < 3; ++a) {
      for (int64_t w = 0; w < grid_.words; ++w) {
        for (uint64_t m = e.mask[a][w]; m; m &= m - 1) {
          const int64_t i = w * 64 + std::countr_zero(m);
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

  void fill_triangles(int64_t j, int64_t k, const RowEdges* const rows[4], const uint32_t base[4],
                      Tri* out) const {
    const uint64_t *a = grid_.row(j, k), *b = grid_.row(j + 1, k), *c = grid_.row(j, k + 1),
                   *d = grid_.row(j + 1, k + 1);
    for (int64_t w = 0; w < grid_.words; ++w) {
      for (uint64_t m = mixed_cells(a, b, c, d, w, grid_.words, grid_.nx); m; m &= m - 1) {
        const int64_t i = w * 64 + std::countr_zero(m);
        const int cs = cell_case(a, b, c, d, i);
        const auto& tris = mc::kCaseTable.triangles[cs];
        const int n = mc::kCaseTable.triangle_count[cs];
        for (int t = 0; t < n; ++t) {
          Tri& tri = *out++;
          for (int v = 0; v < 3; ++v) {
            // Edge e along axis e/4; its other two coordinates are the bits of e%4, lower axis
            // first. Rows: 0 = (j,k), 1 = (j+1,k), 2 = (j,k+1), 3 = (j+1,k+1).
            const int e = tris[3 * t + v], axis = e / 4, m4 = e % 4;
            int row = 0;
            int64_t x = i;
            if (axis == 0) {
              row = m4;  // (dy, dz) = (m4 & 1, m4 >> 1)
            } else if (axis == 1) {
              x += m4 & 1;
              row = (m4 >> 1) << 1;  // dz
            } else {
              x += m4 & 1;
              row = m4 >> 1;  // dy
            }
            tri[v] = base[row] + rows[row]->local_index(axis, x);
          }
        }
      }
    }
  }

  const VolumeView& view_;
  const MarchingCubesOptions& options_;
  const T* data_;
  BitGrid grid_;
};

}  // namespace

Mesh marching_cubes(const VolumeView& view, const MarchingCubesOptions& options) {
  return visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    return Extractor<T>(view, options).run();
  });
}

}  // namespace isotile
