#include "core/extract/dual_contouring.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/errors.h"
#include "core/extract/dual_contouring_patches.h"
#include "core/extract/dual_contouring_table.h"
#include "core/extract/extract.h"
#include "core/extract/inside_bits.h"
#include "core/extract/isovalue_ties.h"
#include "core/extract/marching_cubes_tables.h"
#include "core/extract/scratch_vector.h"

namespace isotile {

namespace dc {

namespace {

double clamp01(double v) {
  return std::min(1.0, std::max(0.0, v));
}

}  // namespace

// Inlined into the extractor's per-cell loop (a call per cell showed in profiles).
inline CellQef accumulate_planes(const HermitePlane* planes, int count, bool with_normals) {
  assert(count >= 1);
  CellQef q{};
  for (int i = 0; i < count; ++i)
    for (int c = 0; c < 3; ++c) q.mass[c] += planes[i].p[c];
  for (double& m : q.mass) m /= count;
  if (!with_normals) return q;
  for (int i = 0; i < count; ++i) {
    const auto& n = planes[i].n;
    const double d = n[0] * planes[i].p[0] + n[1] * planes[i].p[1] + n[2] * planes[i].p[2];
    for (int r = 0; r < 3; ++r) {
      q.b[r] += n[r] * d;
      for (int c = 0; c < 3; ++c) q.a[r][c] += n[r] * n[c];
    }
  }
  return q;
}

CellQef accumulate(const HermitePlane* planes, int count, bool with_normals) {
  return accumulate_planes(planes, count, with_normals);
}

void run_particles(const CellQef* cells, int n, const DualContouringOptions& options,
                   std::array<double, 3>* out) {
  // The paper interpolates corner forces F_k = b - A V_k trilinearly; trilinear weights sum to
  // one and reproduce x, so the interpolant is exactly b - A x, and a step x + c (b - A x) is the
  // affine map (I - c A) x + c b. Each cell's steps form one long dependent chain, so cells run
  // in lanes side by side; every lane does exactly the arithmetic a lone cell would.
  constexpr int kLanes = 8;
  const double c = options.particle_rate;
  const double tol2 = options.particle_tolerance * options.particle_tolerance;
  for (int base = 0; base < n; base += kLanes) {
    const int lanes = std::min(kLanes, n - base);
    // Lanes stop one by one (tolerance); a stopped lane keeps its position and is carried along.
    double m[3][3][kLanes], shift[3][kLanes], x[3][kLanes];
    bool active[kLanes];
    for (int l = 0; l < kLanes; ++l) {
      const CellQef& q = cells[base + std::min(l, lanes - 1)];  // spare lanes repeat the last
      for (int r = 0; r < 3; ++r) {
        shift[r][l] = c * q.b[r];
        x[r][l] = q.mass[r];
        for (int k = 0; k < 3; ++k) m[r][k][l] = (r == k ? 1.0 : 0.0) - c * q.a[r][k];
      }
      active[l] = true;
    }
    for (int step = 0; step < options.particle_steps; ++step) {
      bool any = false;
      for (int l = 0; l < kLanes; ++l) {
        double next[3], moved2 = 0;
        for (int r = 0; r < 3; ++r) {
          next[r] = clamp01(m[r][0][l] * x[0][l] + m[r][1][l] * x[1][l] + m[r][2][l] * x[2][l] +
                            shift[r][l]);
          moved2 += (next[r] - x[r][l]) * (next[r] - x[r][l]);
        }
        if (!active[l]) continue;
        for (int r = 0; r < 3; ++r) x[r][l] = next[r];
        // Measured after the clamp: a particle pinned to a face by an outward force has
        // converged although |c F| stays large.
        active[l] = !(moved2 < tol2);
        any = any || active[l];
      }
      if (!any) break;
    }
    for (int l = 0; l < lanes; ++l) out[base + l] = {x[0][l], x[1][l], x[2][l]};
  }
}

SymmetricEigen symmetric_eigen(const double a[3][3]) {
  // Cyclic Jacobi rotations (as Numerical Recipes' jacobi), at most kJacobiSweeps sweeps: only
  // +, -, *, / and sqrt, so a GPU with IEEE doubles repeats it bit for bit
  // (shaders/glsl/dc_common.glsl mirrors it). A 3x3 matrix converges in about four sweeps.
  double m[3][3], v[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      m[r][c] = a[r][c];
      v[r][c] = r == c ? 1.0 : 0.0;
    }
  constexpr int kPairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  for (int sweep = 0; sweep < kJacobiSweeps; ++sweep) {
    bool rotated = false;  // kJacobiNegligible: once a sweep finds none, the matrix is diagonal
    for (const auto& pq : kPairs) {
      const int p = pq[0], q = pq[1];
      const double apq = m[p][q];
      if (!(std::fabs(apq) > kJacobiNegligible * (std::fabs(m[p][p]) + std::fabs(m[q][q]))))
        continue;
      rotated = true;
      const double theta = (m[q][q] - m[p][p]) / (2.0 * apq);
      double t = 1.0 / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
      if (theta < 0) t = -t;
      const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
      for (int k = 0; k < 3; ++k) {  // columns p and q
        const double mkp = m[k][p], mkq = m[k][q];
        m[k][p] = c * mkp - s * mkq;
        m[k][q] = s * mkp + c * mkq;
      }
      for (int k = 0; k < 3; ++k) {  // rows p and q
        const double mpk = m[p][k], mqk = m[q][k];
        m[p][k] = c * mpk - s * mqk;
        m[q][k] = s * mpk + c * mqk;
      }
      for (int k = 0; k < 3; ++k) {
        const double vkp = v[k][p], vkq = v[k][q];
        v[k][p] = c * vkp - s * vkq;
        v[k][q] = s * vkp + c * vkq;
      }
    }
    if (!rotated) break;
  }
  int order[3] = {0, 1, 2};
  const double lambda[3] = {m[0][0], m[1][1], m[2][2]};
  if (lambda[order[1]] < lambda[order[0]]) std::swap(order[0], order[1]);
  if (lambda[order[2]] < lambda[order[1]]) std::swap(order[1], order[2]);
  if (lambda[order[1]] < lambda[order[0]]) std::swap(order[0], order[1]);
  SymmetricEigen out;
  for (int i = 0; i < 3; ++i) {
    out.value[i] = lambda[order[i]];
    for (int k = 0; k < 3; ++k) out.vector[i][k] = v[k][order[i]];
  }
  return out;
}

std::array<double, 3> solve_qef(const CellQef& q, const DualContouringOptions& options) {
  // Least squares about the mass point, ignoring directions whose eigenvalue is small relative to
  // the largest (the planes barely constrain them), as Ju et al. and libfive do; the truncation
  // also keeps nearly equal small eigenvalues, where eigenvectors are ill-determined, out of the
  // result.
  const SymmetricEigen eigen = symmetric_eigen(q.a);
  double residual[3];
  for (int r = 0; r < 3; ++r)
    residual[r] =
        q.b[r] - ((q.a[r][0] * q.mass[0] + q.a[r][1] * q.mass[1]) + q.a[r][2] * q.mass[2]);
  std::array<double, 3> x = q.mass;
  const double largest = eigen.value[2];
  const double floor = options.qef_eigen_cutoff * largest;
  if (largest > 0)
    for (int e = 0; e < 3; ++e) {
      const double lambda = eigen.value[e];
      if (!(lambda > floor && lambda > 0)) continue;
      const auto& u = eigen.vector[e];
      const double d = ((u[0] * residual[0] + u[1] * residual[1]) + u[2] * residual[2]) / lambda;
      for (int a = 0; a < 3; ++a) x[a] += u[a] * d;
    }
  return {clamp01(x[0]), clamp01(x[1]), clamp01(x[2])};
}

std::array<double, 3> place_vertex(const HermitePlane* planes, int count,
                                   const DualContouringOptions& options) {
  const CellQef q = accumulate(planes, count, options.solver != DcSolver::MassPoint);
  switch (options.solver) {
    case DcSolver::MassPoint:
      return q.mass;
    case DcSolver::Qef:
      return solve_qef(q, options);
    case DcSolver::Particle:
      break;
  }
  std::array<double, 3> x;
  run_particles(&q, 1, options, &x);
  return x;
}

}  // namespace dc

namespace {

using namespace detail;
using std::int64_t;
using std::uint32_t;
using std::uint64_t;

// Bits of word w for the indices [lo, hi) of a row.
inline uint64_t bits_in(int64_t w, int64_t lo, int64_t hi) {
  return valid_bits(w, hi) & ~valid_bits(w, lo);
}

// Mixed cells of one cell row, with the number of vertices of earlier words of the row, so a
// cell's first vertex index is its row's offset + prefix + popcount below it, plus one for each
// extra patch of the cells below it that have several (`multi`, rare).
struct MixedWord {
  uint64_t mask;
  uint64_t multi;  // DcVertices::Patch: cells with more than one patch
  uint32_t prefix;
};

template <class T>
class Extractor {
 public:
  Extractor(const VolumeView& view, const DualContouringOptions& options)
      : view_(view), options_(options), data_(view.typed<T>()) {
    cells_ = local_cell_box(view, options.cells, dual_contouring_halo(options));
    for (int a = 0; a < 3; ++a) {
      vcells_.lo[a] = std::max<int64_t>(cells_.lo[a] - 1, 0);
      vcells_.hi[a] = cells_.hi[a];
    }
    grid_.nx = view.dims[0];
    grid_.ny = view.dims[1];
    grid_.nz = view.dims[2];
    grid_.words = (grid_.nx + 63) / 64;
    patches_ = options.vertices == DcVertices::Patch;
    for (int c = 0; c < 8; ++c) corner_offset_[c] = view.offset(c & 1, (c >> 1) & 1, (c >> 2) & 1);
  }

  // The global keys (cell index with the sample dims as strides) of the vertices, in order.
  std::vector<uint64_t> keys() {
    std::vector<uint64_t> out;
    if (cells_.empty()) return out;
    grid_.bits.resize(static_cast<size_t>(grid_.ny * grid_.nz * grid_.words));
    classify<T>(view_, options_.iso, grid_);
    mixed_.resize(grid_.bits.size());
    tbb::parallel_for(int64_t{0}, grid_.ny * grid_.nz, [&](int64_t r) {
      mark_mixed(r % grid_.ny, r / grid_.ny, mixed_.data() + r * grid_.words);
    });
    const Index3& n = view_.global_dims;
    for (int64_t r = 0; r < grid_.ny * grid_.nz; ++r) {
      const int64_t j = r % grid_.ny, k = r / grid_.ny;
      const uint64_t row = static_cast<uint64_t>(
          n[0] * ((view_.box.lo[1] + j) + n[1] * (view_.box.lo[2] + k)) + view_.box.lo[0]);
      for (int64_t w = 0; w < grid_.words; ++w)
        for (uint64_t m = mixed_[r * grid_.words + w].mask; m; m &= m - 1) {
          const int64_t i = w * 64 + std::countr_zero(m);
          const int patches = patches_ ? patches_at(i, j, k, case_at(i, j, k)).count : 1;
          for (int p = 0; p < patches; ++p)
            out.push_back(4 * (row + static_cast<uint64_t>(i)) + static_cast<uint64_t>(p));
        }
    }
    return out;
  }

  DcPatchRepairs repairs() {
    DcPatchRepairs out;
    if (cells_.empty()) return out;
    grid_.bits.resize(static_cast<size_t>(grid_.ny * grid_.nz * grid_.words));
    classify<T>(view_, options_.iso, grid_);
    for (int64_t k = vcells_.lo[2]; k < vcells_.hi[2]; ++k)
      for (int64_t j = vcells_.lo[1]; j < vcells_.hi[1]; ++j) {
        const uint64_t* rows[4];
        cell_rows(j, k, rows);
        for (int64_t w = 0; w < grid_.words; ++w) {
          const CellWord cw(rows, w, grid_.words, grid_.nx);
          for (uint64_t m = cw.mixed & bits_in(w, vcells_.lo[0], vcells_.hi[0]); m; m &= m - 1) {
            const int b = std::countr_zero(m);
            const int64_t i = w * 64 + b;
            const int cs = cw.cell_case(b);
            const bool border = on_border(i, j, k);
            if (!dc::kConflictFaces[cs] && !border) continue;
            const unsigned flips = flips_at(i, j, k, cs);
            out.flipped_faces += static_cast<uint64_t>(std::popcount(flips & 0b101010u));
            if (!border) continue;
            const int64_t global[3] = {view_.box.lo[0] + i, view_.box.lo[1] + j,
                                       view_.box.lo[2] + k};
            const unsigned open = dc::border_faces(global, view_.global_dims);
            const int cut = dc::cell_patches(cs, flips, open).count;
            out.border_cut_cells += cut > 0 && cut != dc::cell_patches(cs, flips, 0).count;
          }
        }
      }
    return out;
  }

  Mesh run() {
    Mesh mesh;
    if (cells_.empty()) return mesh;
    const int64_t rows = grid_.ny * grid_.nz, words = grid_.words;
    // Progress, in rows of the view (a z-slice at a time): Count is the classification and the
    // count, Extract the vertices and the faces.
    Progress* const progress = options_.progress;
    progress_begin(progress, Stage::Count, 2 * rows);
    grid_.bits.resize(static_cast<size_t>(rows * words));
    classify<T>(view_, options_.iso, grid_, progress);

    // Count: mixed cells per cell row (kept: they index the vertices), quads per sample row.
    reserve_on_caller(mixed_, static_cast<size_t>(rows * words));
    mixed_.resize(static_cast<size_t>(rows * words));
    ScratchVector<uint32_t> vertex_count(rows), quad_count(rows);
    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, rows), for_units(progress, grid_.ny, [&](const auto& range) {
          for (int64_t r = range.begin(); r != range.end(); ++r) {
            const int64_t j = r % grid_.ny, k = r / grid_.ny;
            vertex_count[r] = mark_mixed(j, k, mixed_.data() + r * words);
            uint32_t n = 0;
            for (int64_t w = 0; w < words; ++w) {
              const EdgeWord e = edge_word(j, k, w);
              n += static_cast<uint32_t>(std::popcount(e.active[0]) + std::popcount(e.active[1]) +
                                         std::popcount(e.active[2]));
            }
            quad_count[r] = n;
          }
        }));

    // Scan.
    vertex_offset_.resize(rows + 1);
    ScratchVector<uint64_t> quad_offset(rows + 1);
    vertex_offset_[0] = quad_offset[0] = 0;
    for (int64_t r = 0; r < rows; ++r) {
      vertex_offset_[r + 1] = vertex_offset_[r] + vertex_count[r];
      quad_offset[r + 1] = quad_offset[r] + quad_count[r];
    }
    const uint64_t n_vertices = vertex_offset_[rows], n_quads = quad_offset[rows];
    if (n_vertices > std::numeric_limits<uint32_t>::max())
      throw CapacityError("the mesh would have " + std::to_string(n_vertices) +
                          " vertices, more than an in-memory mesh can index (2^32 - 1)");
    reserve_on_caller(mesh.positions, n_vertices);
    mesh.positions.resize(n_vertices);
    if (options_.normals) {
      reserve_on_caller(mesh.normals, n_vertices);
      mesh.normals.resize(n_vertices);
    }

    // Fill vertices, then faces: splitting a quad looks at its vertices' final positions. The
    // face array is allocated (std::vector zeroes it, a serial pass taking each page's first-touch
    // fault) while the vertices are placed.
    progress_begin(progress, Stage::Extract, 2 * rows);
    if (options_.keep_quads)
      reserve_on_caller(mesh.quads, n_quads);
    else
      reserve_on_caller(mesh.triangles, 2 * n_quads);
    tbb::parallel_invoke(
        [&] {
          if (options_.keep_quads)
            mesh.quads.resize(n_quads);
          else
            mesh.triangles.resize(2 * n_quads);
        },
        [&] {
          tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows),
                            for_units(progress, grid_.ny, [&](const auto& range) {
                              std::vector<dc::CellQef> qef;
                              std::vector<std::array<double, 3>> x;
                              std::vector<int64_t> cell_x;
                              for (int64_t r = range.begin(); r != range.end(); ++r)
                                if (vertex_count[r])
                                  fill_vertices(r % grid_.ny, r / grid_.ny, qef, x, cell_x, mesh);
                            }));
        });
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows),
                      for_units(progress, grid_.ny, [&](const auto& range) {
                        for (int64_t r = range.begin(); r != range.end(); ++r)
                          if (quad_count[r])
                            fill_faces(r % grid_.ny, r / grid_.ny, quad_offset[r], mesh);
                      }));
    return mesh;
  }

 private:
  // Marks the mixed cells of cell row (j, k) (none on the last point rows); returns their count.
  uint32_t mark_mixed(int64_t j, int64_t k, MixedWord* out) const {
    uint32_t total = 0;
    const bool has_cells =
        j >= vcells_.lo[1] && j < vcells_.hi[1] && k >= vcells_.lo[2] && k < vcells_.hi[2];
    const uint64_t* rows[4];
    if (has_cells) cell_rows(j, k, rows);
    for (int64_t w = 0; w < grid_.words; ++w) {
      out[w] = {0, 0, total};
      if (!has_cells) continue;
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      uint64_t m = cw.mixed & bits_in(w, vcells_.lo[0], vcells_.hi[0]);
      // A cell on the volume's border whose crossed edges all lie on it gets no quad, so no
      // vertex (dc::live_edges).
      if (m && border_row(j, k)) {
        for (uint64_t b = m; b; b &= b - 1) {
          const int bit = std::countr_zero(b);
          const int64_t global[3] = {view_.box.lo[0] + w * 64 + bit, view_.box.lo[1] + j,
                                     view_.box.lo[2] + k};
          const unsigned open = dc::border_faces(global, view_.global_dims);
          if (!dc::has_vertex(cw.cell_case(bit), open)) m &= ~(uint64_t{1} << bit);
        }
      }
      out[w].mask = m;
      total += static_cast<uint32_t>(std::popcount(m));
      if (!patches_) continue;
      for (uint64_t b = m; b; b &= b - 1) {
        const int bit = std::countr_zero(b);
        const int cs = cw.cell_case(bit);
        const int64_t i = w * 64 + bit;
        if (dc::kPatchTable.count[cs] == 1 && !dc::kConflictFaces[cs] && !on_border(i, j, k))
          continue;
        const int extra = patches_at(i, j, k, cs).count - 1;
        if (extra > 0) {
          out[w].multi |= uint64_t{1} << bit;
          total += static_cast<uint32_t>(extra);
        }
      }
    }
    return total;
  }

  // MC case of cell (i, j, k) from the classification.
  int case_at(int64_t i, int64_t j, int64_t k) const {
    int cs = 0;
    for (int c = 0; c < 8; ++c) {
      const int64_t x = i + (c & 1);
      const uint64_t word = grid_.row(j + ((c >> 1) & 1), k + ((c >> 2) & 1))[x >> 6];
      cs |= static_cast<int>((word >> (x & 63)) & 1) << c;
    }
    return cs;
  }

  // Whether cells of row (j, k) can lie on the volume's border: the row is on it in y or z, or
  // the view reaches the border in x.
  bool border_row(int64_t j, int64_t k) const {
    const int64_t gj = view_.box.lo[1] + j, gk = view_.box.lo[2] + k;
    const int64_t gx0 = view_.box.lo[0] + vcells_.lo[0], gx1 = view_.box.lo[0] + vcells_.hi[0];
    return gj == 0 || gj + 2 == view_.global_dims[1] || gk == 0 || gk + 2 == view_.global_dims[2] ||
           gx0 == 0 || gx1 + 1 >= view_.global_dims[0];
  }

  bool on_border(int64_t i, int64_t j, int64_t k) const {
    const int64_t p[3] = {i, j, k};
    for (int a = 0; a < 3; ++a) {
      const int64_t global = view_.box.lo[a] + p[a];
      if (global == 0 || global + 2 == view_.global_dims[a]) return true;
    }
    return false;
  }

  // The patches of cell (i, j, k) of case cs (dual_contouring_patches.h). A neighbour beyond the
  // view counts as absent: brick mode's halo holds every neighbour inside the volume.
  // The faces of cell (i, j, k) of case cs that flip (dual_contouring_patches.h).
  unsigned flips_at(int64_t i, int64_t j, int64_t k, int cs) const {
    return dc::face_flips(cs, [&](int f) {
      const auto& d = dc::kFaceNeighbour[f];
      const int64_t p[3] = {i + d[0], j + d[1], k + d[2]};
      for (int a = 0; a < 3; ++a)
        if (p[a] < 0 || p[a] + 1 >= view_.dims[a]) return -1;
      return case_at(p[0], p[1], p[2]);
    });
  }

  dc::CellPatches patches_at(int64_t i, int64_t j, int64_t k, int cs) const {
    const unsigned flips = flips_at(i, j, k, cs);
    const int64_t global[3] = {view_.box.lo[0] + i, view_.box.lo[1] + j, view_.box.lo[2] + k};
    return dc::cell_patches_or_table(cs, flips, dc::border_faces(global, view_.global_dims));
  }

  void cell_rows(int64_t j, int64_t k, const uint64_t* rows[4]) const {
    rows[0] = grid_.row(j, k);
    rows[1] = grid_.row(j + 1, k);
    rows[2] = grid_.row(j, k + 1);
    rows[3] = grid_.row(j + 1, k + 1);
  }

  // The crossed edges owned by 64 samples of row (j, k) that get a quad: those of samples in the
  // cell box whose four cells all exist (are vertex cells). The x-edge of (i, j, k) needs cells at
  // j-1, j and k-1, k; the y-edge cells at i-1, i and k-1, k; the z-edge cells at i-1, i and j-1,
  // j. Cells up to the box's upper end are vertex cells, so only the lower neighbours need
  // checking.
  struct EdgeWord {
    uint64_t origin;     // inside bits of the samples
    uint64_t active[3];  // per axis
  };
  EdgeWord edge_word(int64_t j, int64_t k, int64_t w) const {
    const uint64_t* a = grid_.row(j, k);
    EdgeWord e{a[w], {0, 0, 0}};
    if (j < cells_.lo[1] || j >= cells_.hi[1] || k < cells_.lo[2] || k >= cells_.hi[2]) return e;
    const bool mid_j = j > vcells_.lo[1], mid_k = k > vcells_.lo[2];
    const uint64_t in_i = bits_in(w, cells_.lo[0], cells_.hi[0]);
    const uint64_t mid_i = in_i & bits_in(w, vcells_.lo[0] + 1, cells_.hi[0]);
    if (mid_j && mid_k) e.active[0] = (a[w] ^ shifted(a, w, grid_.words)) & in_i;
    if (mid_k) e.active[1] = (a[w] ^ grid_.row(j + 1, k)[w]) & mid_i;
    if (mid_j) e.active[2] = (a[w] ^ grid_.row(j, k + 1)[w]) & mid_i;
    return e;
  }

  double sample(int64_t i, int64_t j, int64_t k) const {
    return static_cast<double>(data_[view_.offset(i, j, k)]);
  }

  // Gradient in index space (per voxel, not per world unit): normals in cell-local coordinates
  // are what the QEF needs. Central differences, one-sided only at the border of the whole volume
  // (never at a brick's, so bricks agree; x / 2 and 0.5 * x round alike, so both paths give the
  // same bits). A view's own border is reached only when every cell of a view that is part of a
  // larger volume is extracted without a halo; brick mode checks the halo up front.
  std::array<double, 3> gradient(int64_t i, int64_t j, int64_t k, bool interior) const {
    std::array<double, 3> g{};
    if (interior) {
      const T* c = data_ + view_.offset(i, j, k);
      for (int a = 0; a < 3; ++a) {
        const int64_t s = view_.strides[a];
        g[a] = 0.5 * (static_cast<double>(c[s]) - static_cast<double>(c[-s]));
      }
      return g;
    }
    const int64_t p[3] = {i, j, k};
    for (int a = 0; a < 3; ++a) {
      int64_t lo[3] = {i, j, k}, hi[3] = {i, j, k};
      const int64_t global = view_.box.lo[a] + p[a];
      if (global > 0 && p[a] > 0) lo[a] = p[a] - 1;
      if (global + 1 < view_.global_dims[a] && p[a] + 1 < view_.dims[a]) hi[a] = p[a] + 1;
      const int64_t h = hi[a] - lo[a];
      g[a] = h > 0 ? (sample(hi[0], hi[1], hi[2]) - sample(lo[0], lo[1], lo[2])) /
                         static_cast<double>(h)
                   : 0.0;
    }
    return g;
  }

  // Cells whose corners all have both neighbours along every axis skip the border checks.
  bool interior(int64_t i, int64_t j, int64_t k) const {
    return i >= 1 && i + 2 < grid_.nx && j >= 1 && j + 2 < grid_.ny && k >= 1 && k + 2 < grid_.nz;
  }

  std::array<double, 3> corner_gradient(int64_t i, int64_t j, int64_t k, int c, bool inner) const {
    return gradient(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1), inner);
  }

  // The Hermite planes of the crossed edges `edges` (a mask over MC's edge numbers) of cell
  // (i, j, k); returns their number. Normals only
  // when the solver uses them (the mass point does not).
  int hermite(int64_t i, int64_t j, int64_t k, unsigned edges, bool with_normals,
              dc::HermitePlane* planes) const {
    double value[8];
    const T* origin = data_ + view_.offset(i, j, k);
    for (int c = 0; c < 8; ++c) value[c] = static_cast<double>(origin[corner_offset_[c]]);
    const bool inner = interior(i, j, k);
    std::array<double, 3> grad[8];
    unsigned have = 0;
    int count = 0;
    for (unsigned em = edges; em; em &= em - 1) {
      const int e = std::countr_zero(em), axis = e / 4;
      const int c0 = mc::kEdgeCorners[e][0], c1 = mc::kEdgeCorners[e][1];
      dc::HermitePlane& h = planes[count++];
      if (options_.hermite == DcHermite::Eno) {
        eno_plane(i, j, k, c0, axis, value[c0], value[c1], with_normals, h);
        continue;
      }
      const int64_t s0[3] = {i + (c0 & 1), j + ((c0 >> 1) & 1), k + ((c0 >> 2) & 1)};
      double t = (options_.iso - value[c0]) / (value[c1] - value[c0]);
      tie_crossing(s0, axis, value[c0], value[c1], t);
      for (int a = 0; a < 3; ++a) h.p[a] = static_cast<double>((c0 >> a) & 1);
      h.p[axis] = t;
      h.n = {0, 0, 0};
      if (!with_normals) continue;
      for (int c : {c0, c1})
        if (!((have >> c) & 1)) {
          grad[c] = corner_gradient(i, j, k, c, inner);
          have |= 1u << c;
        }
      double len2 = 0;
      for (int a = 0; a < 3; ++a) {
        h.n[a] = grad[c0][a] + t * (grad[c1][a] - grad[c0][a]);
        len2 += h.n[a] * h.n[a];
      }
      const double inv = len2 > 0 ? 1.0 / std::sqrt(len2) : 0.0;
      for (double& n : h.n) n *= inv;
    }
    return count;
  }

  // Whether an end of the edge from sample s0 along `axis` (values f0, f1) is a pinned tie
  // (core/extract/isovalue_ties.h); if so, t becomes kTieOffset from that end.
  bool tie_crossing(const int64_t s0[3], int axis, double f0, double f1, double& t) const {
    const double iso = options_.iso;
    if (f0 != iso && f1 != iso) return false;
    int64_t s[3] = {s0[0], s0[1], s0[2]};
    if (f1 == iso) ++s[axis];
    for (int a = 0; a < 3; ++a) {
      int outside = 0;
      for (int dir = -1; dir <= 1; dir += 2) {
        const int64_t global = view_.box.lo[a] + s[a] + dir;
        if (global < 0 || global >= view_.global_dims[a]) continue;
        int64_t q[3] = {s[0], s[1], s[2]};
        q[a] += dir;
        outside += sample(q[0], q[1], q[2]) < iso;
      }
      if (outside == 2) {
        t = f0 == iso ? detail::kTieOffset : 1 - detail::kTieOffset;
        return true;
      }
    }
    return false;
  }

  // Does the line of samples p + d e_axis, d in [lo, hi], lie in the volume and in the view?
  bool line_inside(const int64_t p[3], int axis, int lo, int hi) const {
    const int64_t global = view_.box.lo[axis] + p[axis];
    return global + lo >= 0 && global + hi < view_.global_dims[axis] && p[axis] + lo >= 0 &&
           p[axis] + hi < view_.dims[axis];
  }
  double at(const int64_t p[3], int axis, int d) const {
    return static_cast<double>(data_[view_.offset(p[0], p[1], p[2]) + d * view_.strides[axis]]);
  }

  // One component of the ENO gradient at sample p: the one-sided difference on the side where
  // the field bends clearly less (second difference under a quarter of the other side's). Near a
  // sharp feature the field is often linear on one side and kinked on the other; the central
  // difference mixes both and tilts the normal by tens of degrees. Where both sides bend, a kink
  // that the two-piece test of eno_plane finds on the edge to one side of p and not on the other
  // still takes the difference away from it: csg-box N = 50 has samples a fifth of a voxel from a
  // box face whose values run 0.0085, 0.0028, 0.0004 | -0.033 along the axis, and the central
  // difference there mixed the face's slope into the ball's normal (23 degrees). Only then the
  // central difference. Reads three samples either side.
  double eno_component(const int64_t p[3], int axis) const {
    if (!line_inside(p, axis, -2, 2)) {
      const auto g = gradient(p[0], p[1], p[2], false);
      return g[axis];
    }
    const double fm2 = at(p, axis, -2), fm = at(p, axis, -1), f0 = at(p, axis, 0);
    const double fp = at(p, axis, 1), fp2 = at(p, axis, 2);
    const double bend_up = std::fabs(fp2 - 2 * fp + f0), bend_down = std::fabs(f0 - 2 * fm + fm2);
    if (bend_up < 0.25 * bend_down) return fp - f0;
    if (bend_down < 0.25 * bend_up) return f0 - fm;
    if (line_inside(p, axis, -3, 3)) {
      // The edge need not be crossed and its rise may vanish (a tangent direction near an
      // extremum of the line), so "large" is measured against the largest rise of the edge and
      // its two neighbours.
      const double rise = std::max(std::fabs(f0 - fm), std::fabs(fp - f0));
      const bool down =
          Pieces(at(p, axis, -3), fm2, fm, f0, fp, fp2).kinked(std::max(rise, std::fabs(fm - fm2)));
      const bool up =
          Pieces(fm2, fm, f0, fp, fp2, at(p, axis, 3)).kinked(std::max(rise, std::fabs(fp2 - fp)));
      if (up != down) return up ? f0 - fm : fp - f0;
    }
    return 0.5 * (fp - fm);
  }

  // The two quadratic pieces of an edge from sample 0 to sample 1, on a line of samples -2..3
  // (eno_plane): p0(t) = f0 + b0 t + a0 t^2 through -2, -1, 0 and p1(t) = f1 + b1 s + a1 s^2, s =
  // t - 1, through 1, 2, 3, and how far each misses the other end (e0 = p0(1) - f1, e1 = p1(0) -
  // f0).
  struct Pieces {
    Pieces(double fm2, double fm, double f0, double f1, double f2, double f3)
        : a0(0.5 * (f0 - 2 * fm + fm2)),
          b0((f0 - fm) + a0),
          a1(0.5 * (f3 - 2 * f2 + f1)),
          b1((f2 - f1) - a1),
          e0((f0 + b0 + a0) - f1),
          e1((f1 - b1 + a1) - f0) {}
    // A kink at or between the edge's samples: where the field is smooth across the edge the
    // misses are about the third difference with opposite signs (e0 = -e1 for a cubic); a kink
    // makes them share a sign, and the larger exceed kEnoKink of `rise` (see eno_plane).
    bool kinked(double rise) const {
      return !(e0 * e1 < 0) && std::max(std::fabs(e0), std::fabs(e1)) > dc::kEnoKink * rise;
    }
    double a0, b0, a1, b1, e0, e1;
  };

  // The root in [lo, hi] of a x^2 + b x + c, which changes sign there, from the form of the
  // quadratic formula that does not cancel, clamped against rounding. a = 0 makes q = -b and
  // c / q the linear root (q / a is then infinite); a NaN ends at lo.
  static double bracketed_root(double a, double b, double c, double lo, double hi) {
    const double q = -0.5 * (b + std::copysign(std::sqrt(std::max(b * b - 4 * a * c, 0.0)), b));
    const double ra = q / a, rc = c / q;
    const double r = ra >= lo && ra <= hi ? ra : rc;
    return std::min(hi, std::max(lo, r));
  }

  // DcHermite::Eno: the crossing and normal of the edge from corner c0 of cell (i, j, k) along
  // `axis`. A sharp feature puts a kink in the field between the edge's samples, where the chord
  // misplaces the root (csg-box: by up to half a voxel where a curved face meets a flat one).
  // Near a kink the field is taken as two smooth pieces: p0, the quadratic through samples -2,
  // -1, 0 (the edge's lower end and the two before it), and p1, the quadratic through 1, 2, 3.
  // Where the field is smooth across the edge, each piece extrapolated to the other end misses
  // that sample by about the third difference, with opposite signs (e0 = -e1 for a cubic). A
  // kink at or between the edge's samples makes both misses the same sign, large: the field is
  // then min(p0, p1) (both misses >= 0) or max(p0, p1) (both <= 0), and the crossing is the first
  // root of that in [0, 1]; it lies on one piece, whose derivative gives the slope along the edge.
  // The normal across the edge is that side's end sample's ENO gradient: the other end lies
  // beyond, or on, the kink. The pieces need not be straight: where a curved face meets a flat one
  // (csg-box's ball and box) the curved side bends, and lines through two samples miss the root.
  // Otherwise: the chord, and ENO gradients interpolated along the edge.
  void eno_plane(int64_t i, int64_t j, int64_t k, int c0, int axis, double f0, double f1,
                 bool with_normals, dc::HermitePlane& h) const {
    const int64_t s0[3] = {i + (c0 & 1), j + ((c0 >> 1) & 1), k + ((c0 >> 2) & 1)};
    int64_t s1[3] = {s0[0], s0[1], s0[2]};
    ++s1[axis];
    const double iso = options_.iso;
    double t = (iso - f0) / (f1 - f0), slope = f1 - f0;
    int side = -1;  // 0: the root is on p0, 1: on p1, -1: the chord's
    if (tie_crossing(s0, axis, f0, f1, t)) {
      // The offset crossing, with the chord's slope and normals.
    } else if (line_inside(s0, axis, -2, 3)) {
      const Pieces q(at(s0, axis, -2), at(s0, axis, -1), f0, f1, at(s0, axis, 2), at(s0, axis, 3));
      const double a0 = q.a0, b0 = q.b0, a1 = q.a1, b1 = q.b1, e0 = q.e0, e1 = q.e1;
      // Large: 0.4 of the edge's rise. A smaller threshold also catches smooth but tightly
      // curved stretches (torus N = 32, tube radius 3 voxels): their piece roots are better
      // than the chord, yet the QEF vertex, which sits on the tangent planes' intersection, then
      // strays further from a convex surface (docs/quality.md). csg-box keeps its accuracy up to
      // 0.7, not at 1.0 (a kink exactly at a sample between slopes 1 and 0 misses by the rise).
      if (q.kinked(std::fabs(f1 - f0))) {
        // In g = sign (f - iso), sign chosen so the field is min(p0, p1) there: both pieces
        // then lie above g at the other end, so the piece ending below zero changes sign on the
        // edge and has exactly one root in it.
        const double sign = e0 + e1 > 0 ? 1.0 : -1.0;
        const double g0 = sign * (f0 - iso), g1 = sign * (f1 - iso);
        const double ga0 = sign * a0, gb0 = sign * b0, ga1 = sign * a1, gb1 = sign * b1;
        // Falling (g0 > g1): the first root of min(p0, p1). p1 falls from >= g0 >= 0 to g1 <=
        // 0; p0 ends at p0(1) >= g1 and has a root only when it ends below zero. Rising: min(p0,
        // p1) turns positive where the later of the two does; p0 rises from g0 <= 0 to >= g1,
        // and p1 has a root only when it starts below zero.
        const bool falling = g0 > g1;
        const double t0 = bracketed_root(ga0, gb0, g0, 0, 1);
        const double t1 = 1 + bracketed_root(ga1, gb1, g1, -1, 0);
        const bool on_p1 =
            falling ? !(g1 + sign * e0 < 0 && t0 < t1) : (g0 + sign * e1 < 0 && t1 > t0);
        side = on_p1 ? 1 : 0;
        t = side == 0 ? t0 : t1;
        slope = side == 0 ? b0 + 2 * a0 * t : b1 + 2 * a1 * (t - 1);
      }
    }
    for (int a = 0; a < 3; ++a) h.p[a] = static_cast<double>((c0 >> a) & 1);
    h.p[axis] = t;
    h.n = {0, 0, 0};
    if (!with_normals) return;
    double len2 = 0;
    for (int a = 0; a < 3; ++a) {
      if (a == axis) {
        h.n[a] = slope;
      } else if (side == 0) {
        h.n[a] = eno_component(s0, a);
      } else if (side == 1) {
        h.n[a] = eno_component(s1, a);
      } else {
        const double g0 = eno_component(s0, a), g1 = eno_component(s1, a);
        h.n[a] = g0 + t * (g1 - g0);
      }
      len2 += h.n[a] * h.n[a];
    }
    const double inv = len2 > 0 ? 1.0 / std::sqrt(len2) : 0.0;
    for (double& n : h.n) n *= inv;
  }

  // Outward unit normal at cell-local x: the corner gradients interpolated trilinearly, in world
  // units (zero where they cancel, as in MC).
  Vec3f vertex_normal(int64_t i, int64_t j, int64_t k, const std::array<double, 3>& x) const {
    const bool inner = interior(i, j, k);
    double n[3] = {0, 0, 0}, len2 = 0;
    for (int c = 0; c < 8; ++c) {
      const auto g = corner_gradient(i, j, k, c, inner);
      double weight = 1;
      for (int a = 0; a < 3; ++a) weight *= ((c >> a) & 1) ? x[a] : 1 - x[a];
      for (int a = 0; a < 3; ++a) n[a] -= weight * g[a] / view_.spacing[a];
    }
    for (double v : n) len2 += v * v;
    const double inv = len2 > 0 ? 1.0 / std::sqrt(len2) : 0.0;
    return {static_cast<float>(n[0] * inv), static_cast<float>(n[1] * inv),
            static_cast<float>(n[2] * inv)};
  }

  // One row of cells in three sweeps (Hermite data, solve, write), so particles can run many
  // cells abreast. `qef` and `x` are scratch reused across rows.
  void fill_vertices(int64_t j, int64_t k, std::vector<dc::CellQef>& qef,
                     std::vector<std::array<double, 3>>& x, std::vector<int64_t>& cell_x,
                     Mesh& mesh) const {
    const int64_t r = k * grid_.ny + j;
    const uint64_t first = vertex_offset_[r];
    const size_t n = static_cast<size_t>(vertex_offset_[r + 1] - first);
    // The mass point needs no QEF: its vertex is written straight into x, as
    // accumulate_planes() computes it, without zeroing and copying 15 doubles per cell.
    const bool with_normals = options_.solver != DcSolver::MassPoint;
    if (with_normals) qef.resize(n);
    x.resize(n);
    cell_x.resize(n);
    const uint64_t* rows[4];
    cell_rows(j, k, rows);
    const MixedWord* mixed = mixed_.data() + r * grid_.words;
    size_t v = 0;
    for (int64_t w = 0; w < grid_.words; ++w) {
      if (!mixed[w].mask) continue;
      const CellWord cw(rows, w, grid_.words, grid_.nx);
      for (uint64_t m = mixed[w].mask; m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int cs = cw.cell_case(b);
        dc::CellPatches cp;
        if (patches_) {
          cp = patches_at(w * 64 + b, j, k, cs);
        } else {
          cp.count = 1;
          cp.edges[0] = mc::kCaseTable.edge_mask[cs];
        }
        for (int p = 0; p < cp.count; ++p) {
          const unsigned edges = cp.edges[p];
          dc::HermitePlane planes[12];
          const int count = hermite(w * 64 + b, j, k, edges, with_normals, planes);
          cell_x[v] = w * 64 + b;
          if (with_normals) {
            qef[v++] = dc::accumulate_planes(planes, count, true);
            continue;
          }
          std::array<double, 3>& mass = x[v++];
          mass = {0, 0, 0};
          for (int i = 0; i < count; ++i)
            for (int c = 0; c < 3; ++c) mass[c] += planes[i].p[c];
          for (double& m : mass) m /= count;
        }
      }
    }
    assert(v == n);

    switch (options_.solver) {
      case DcSolver::MassPoint:
        break;  // x holds the mass points already
      case DcSolver::Qef:
        for (size_t c = 0; c < n; ++c) x[c] = dc::solve_qef(qef[c], options_);
        break;
      case DcSolver::Particle:
        dc::run_particles(qef.data(), static_cast<int>(n), options_, x.data());
        break;
    }

    for (v = 0; v < n; ++v) {
      const int64_t cell[3] = {cell_x[v], j, k};
      const size_t index = first + v;
      Vec3f& pos = mesh.positions[index];
      for (int a = 0; a < 3; ++a)
        pos[a] = static_cast<float>(view_.origin[a] +
                                    view_.spacing[a] *
                                        (static_cast<double>(view_.box.lo[a] + cell[a]) + x[v][a]));
      if (options_.normals) mesh.normals[index] = vertex_normal(cell[0], j, k, x[v]);
    }
  }

  // The vertex of cell (i, j, k) that serves its MC edge `edge` (with DcVertices::Cell, its one).
  uint32_t vertex_of_cell(int64_t i, int64_t j, int64_t k, int edge) const {
    const int64_t r = k * grid_.ny + j;
    const MixedWord& mw = mixed_[r * grid_.words + (i >> 6)];
    assert((mw.mask >> (i & 63)) & 1);
    const uint64_t lower = (uint64_t{1} << (i & 63)) - 1;
    uint64_t index = vertex_offset_[r] + mw.prefix + std::popcount(mw.mask & lower);
    if (mw.multi) {
      const int64_t w0 = i & ~int64_t{63};
      for (uint64_t m = mw.multi & lower; m; m &= m - 1) {
        const int64_t x = w0 + std::countr_zero(m);
        index += patches_at(x, j, k, case_at(x, j, k)).count - 1;
      }
      if ((mw.multi >> (i & 63)) & 1) index += patches_at(i, j, k, case_at(i, j, k)).patch[edge];
    }
    return static_cast<uint32_t>(index);
  }

  void fill_faces(int64_t j, int64_t k, uint64_t first, Mesh& mesh) const {
    uint64_t out = first;
    for (int64_t w = 0; w < grid_.words; ++w) {
      const EdgeWord e = edge_word(j, k, w);
      for (uint64_t m = e.active[0] | e.active[1] | e.active[2]; m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t i = w * 64 + b;
        // An edge without a quad (border) is given its origin's bit, so the table skips it.
        const unsigned o = (e.origin >> b) & 1;
        unsigned code = o << 3;
        for (int a = 0; a < 3; ++a) code |= (o ^ ((e.active[a] >> b) & 1)) << a;
        const dc::DcCase& cs = dc::kDcTable[code];
        for (int q = 0; q < cs.count; ++q) {
          Quad quad;
          for (int v = 0; v < 4; ++v) {
            const int n = cs.quads[q][v];
            const auto& d = dc::kBlockCell[n];
            quad[v] = vertex_of_cell(i + d[0], j + d[1], k + d[2], dc::kBlockEdge[n][cs.axis[q]]);
          }
          if (options_.keep_quads) {
            mesh.quads[out++] = quad;
          } else {
            split(mesh.positions, quad, mesh.triangles.data() + 2 * out);
            ++out;
          }
        }
      }
    }
  }

  // The rule of triangle_quality's quad measure (0-2 unless 1-3 leaves a strictly better worst
  // triangle), so splitting here and measuring kept quads agree. The four triangles share six
  // edge lengths; each is computed once, exactly as radius_ratio() computes it
  // (mesh_quality.cpp), and combined in radius_ratio's order, which gives its values bit for bit
  // at half the square roots (a test compares the two).
  static double length(const Vec3f& p, const Vec3f& q) {
    const double dx = double{p[0]} - q[0], dy = double{p[1]} - q[1], dz = double{p[2]} - q[2];
    return std::sqrt(dx * dx + dy * dy + dz * dz);
  }
  static double ratio(double la, double lb, double lc) {
    if (la == 0 || lb == 0 || lc == 0) return 0;
    const double q = (lb + lc - la) * (lc + la - lb) * (la + lb - lc) / (la * lb * lc);
    if (!(q > 0)) return 0;
    return std::min(q, 1.0);
  }
  static void split(const std::vector<Vec3f>& p, const Quad& q, Tri* out) {
    const Vec3f &p0 = p[q[0]], &p1 = p[q[1]], &p2 = p[q[2]], &p3 = p[q[3]];
    const double s01 = length(p0, p1), s12 = length(p1, p2), s23 = length(p2, p3);
    const double s30 = length(p3, p0), d02 = length(p0, p2), d13 = length(p1, p3);
    const double a = std::min(ratio(s12, d02, s01), ratio(s23, s30, d02));  // (0,1,2), (0,2,3)
    const double b = std::min(ratio(d13, s30, s01), ratio(s23, d13, s12));  // (0,1,3), (1,2,3)
    // Which diagonal wins is a coin toss to the branch predictor; select without branching.
    const bool d13_wins = b > a;
    out[0] = {q[0], q[1], d13_wins ? q[3] : q[2]};
    out[1] = {d13_wins ? q[1] : q[0], q[2], q[3]};
  }

  const VolumeView& view_;
  const DualContouringOptions& options_;
  const T* data_;
  Box3 cells_;   // the cells whose faces are wanted, in the view's indices
  Box3 vcells_;  // the cells that get vertices: cells_ and the layer below it, within the view
  BitGrid grid_;
  ScratchVector<MixedWord> mixed_;  // mark_mixed() writes every word
  int64_t corner_offset_[8];        // of a cell's corner c from its corner 0, in samples
  bool patches_ = false;            // DcVertices::Patch
  ScratchVector<uint64_t> vertex_offset_;
};

}  // namespace

int dual_contouring_halo(const DualContouringOptions& options) {
  // Vertex cells start one below the box; gradients reach one sample beyond their corners.
  // DcHermite::Eno's gradients read three samples beyond a corner (their kink tests): four
  // beyond the box.
  if (options.hermite == DcHermite::Eno) return 4;
  // The tie test (core/extract/isovalue_ties.h) reads the corners' neighbours too: 2 in any case.
  return 2;
}

namespace {
void check_options(const DualContouringOptions& options) {
  if (options.particle_steps < 0)
    throw InputError("dual contouring: particle_steps must be >= 0, got " +
                     std::to_string(options.particle_steps));
  if (!(options.particle_rate > 0))
    throw InputError("dual contouring: particle_rate must be positive");
}
}  // namespace

std::vector<std::uint64_t> dual_contouring_vertex_keys(const VolumeView& view,
                                                       const DualContouringOptions& options) {
  check_options(options);
  return visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    return Extractor<T>(view, options).keys();
  });
}

DcPatchRepairs dual_contouring_patch_repairs(const VolumeView& view, double iso) {
  DualContouringOptions options;
  options.iso = iso;
  return visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    return Extractor<T>(view, options).repairs();
  });
}

Mesh dual_contouring(const VolumeView& view, const DualContouringOptions& options) {
  check_extraction_input(view, options.iso);
  check_options(options);
  return visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    return Extractor<T>(view, options).run();
  });
}

}  // namespace isotile
