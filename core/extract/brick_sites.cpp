#include "core/extract/brick_sites.h"

#include <tbb/parallel_for.h>

#include <bit>
#include <string>

#include "core/errors.h"
#include "core/extract/dual_contouring_patches.h"
#include "core/extract/inside_bits.h"
#include "core/extract/marching_cubes.h"
#include "core/extract/marching_cubes_tables.h"

namespace isotile {

namespace {

using namespace detail;
using std::int64_t;
using std::uint32_t;
using std::uint64_t;

// The view's samples classified, with the bookkeeping to address them by global index.
struct Classified {
  BitGrid grid;
  Index3 lo;  // global index of the view's sample (0, 0, 0)
  Index3 n;   // global dims

  // Row (j, k) in global indices; nullptr outside the view.
  const uint64_t* row(int64_t j, int64_t k) const {
    j -= lo[1];
    k -= lo[2];
    if (j < 0 || k < 0 || j >= grid.ny || k >= grid.nz) return nullptr;
    return grid.row(j, k);
  }
};

Classified classify_view(const VolumeView& view, double iso) {
  Classified c;
  c.grid.nx = view.dims[0];
  c.grid.ny = view.dims[1];
  c.grid.nz = view.dims[2];
  c.grid.words = (c.grid.nx + 63) / 64;
  c.grid.bits.resize(static_cast<size_t>(c.grid.ny * c.grid.nz * c.grid.words));
  c.lo = view.box.lo;
  c.n = view.global_dims;
  visit_scalar(view.type, [&](auto tag) { classify<decltype(tag)>(view, iso, c.grid); });
  return c;
}

// The view must hold the samples [box.lo, box.hi + extra) (clipped to the volume) for each box.
void require(const VolumeView& view, const Box3& box, int extra) {
  for (int a = 0; a < 3; ++a) {
    const int64_t hi = std::min<int64_t>(box.hi[a] + extra, view.global_dims[a]);
    if (box.lo[a] < view.box.lo[a] || hi > view.box.hi[a])
      throw InputError("brick sites: the view (samples " + std::to_string(view.box.lo[a]) + ".." +
                       std::to_string(view.box.hi[a] - 1) + " along axis " + std::to_string(a) +
                       ") does not hold the samples the counts need (" + std::to_string(box.lo[a]) +
                       ".." + std::to_string(hi - 1) + ")");
  }
}

// The MC case of global cell (x, y, z); -1 when the volume or the view lacks one of its samples.
int case_at(const Classified& c, int64_t x, int64_t y, int64_t z) {
  if (x < 0 || y < 0 || z < 0 || x + 1 >= c.n[0] || y + 1 >= c.n[1] || z + 1 >= c.n[2]) return -1;
  const int64_t lx = x - c.lo[0];
  if (lx < 0 || lx + 1 >= c.grid.nx) return -1;
  int cs = 0;
  for (int corner = 0; corner < 8; ++corner) {
    const uint64_t* row = c.row(y + ((corner >> 1) & 1), z + ((corner >> 2) & 1));
    if (!row) return -1;
    const int64_t b = lx + (corner & 1);
    cs |= static_cast<int>((row[b >> 6] >> (b & 63)) & 1) << corner;
  }
  return cs;
}

// Vertices of global cell (x, y, z) of case cs with DcVertices::Patch.
int patch_count(const Classified& c, int64_t x, int64_t y, int64_t z, int cs) {
  const int64_t cell[3] = {x, y, z};
  const unsigned open = dc::border_faces(cell, c.n);
  if (!dc::kConflictFaces[cs] && !open) return dc::kPatchTable.count[cs];
  const unsigned flips = dc::face_flips(cs, [&](int f) {
    const auto& d = dc::kFaceNeighbour[f];
    return case_at(c, x + d[0], y + d[1], z + d[2]);
  });
  return dc::cell_patches_or_table(cs, flips, open).count;
}

// Vertices of global cell (x, y, z) of case cs: its patches, or one (DcVertices::Cell); none
// where its crossed edges all lie on the volume's border (dc::live_edges), as the extractor has.
int cell_vertex_count(const Classified& c, int64_t x, int64_t y, int64_t z, int cs, bool patches) {
  if (patches) return patch_count(c, x, y, z, cs);
  const int64_t cell[3] = {x, y, z};
  const unsigned open = dc::border_faces(cell, c.n);
  return dc::has_vertex(cs, open) ? 1 : 0;
}

template <class Fn>
RowCounts per_row(const Box3& box, Fn&& count_row) {
  RowCounts out{box, {}};
  if (box.empty()) return out;
  const int64_t ny = box.extent(1), rows = ny * box.extent(2);
  out.count.resize(static_cast<size_t>(rows));
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, rows), [&](const auto& range) {
    for (int64_t r = range.begin(); r != range.end(); ++r)
      out.count[r] = count_row(box.lo[1] + r % ny, box.lo[2] + r / ny);
  });
  return out;
}

// Masks of the crossed edges of global row (j, k), local word w, per axis; an edge counts only
// when its far end is inside the volume. `quads`: only edges whose four cells exist.
void edge_masks(const Classified& c, int64_t j, int64_t k, int64_t w, bool quads, uint64_t m[3]) {
  const BitGrid& g = c.grid;
  const uint64_t* a = c.row(j, k);
  const uint64_t* b = j + 1 < c.n[1] ? c.row(j + 1, k) : nullptr;
  const uint64_t* d = k + 1 < c.n[2] ? c.row(j, k + 1) : nullptr;
  const int64_t x_last = c.n[0] - 1 - c.lo[0];  // local x of the volume's last sample
  m[0] = (a[w] ^ shifted(a, w, g.words)) & valid_bits(w, x_last);
  m[1] = b ? (a[w] ^ b[w]) : 0;
  m[2] = d ? (a[w] ^ d[w]) : 0;
  if (quads) {
    // Four cells around the edge: the other two coordinates in [1, N - 2].
    const bool mid_j = j >= 1 && j + 1 < c.n[1], mid_k = k >= 1 && k + 1 < c.n[2];
    const uint64_t mid_x = range_bits(w, 1 - c.lo[0], x_last);
    if (!(mid_j && mid_k)) m[0] = 0;
    if (!mid_k) m[1] = 0;
    if (!mid_j) m[2] = 0;
    m[1] &= mid_x;
    m[2] &= mid_x;
  }
}

}  // namespace

BrickCounts count_brick_sites(const VolumeView& view, double iso, SiteLayout layout,
                              const Box3& vertex_box, const Box3& face_box) {
  // Edges reach one sample beyond their site; cells one sample beyond theirs.
  // Patches look at the cells across their faces: one sample more on every side.
  const int more = layout == SiteLayout::PatchVertices ? 1 : 0;
  Box3 wider = vertex_box;
  for (int a = 0; a < 3; ++a) wider.lo[a] = std::max<int64_t>(wider.lo[a] - more, 0);
  require(view, wider, 1 + more);
  require(view, face_box, 1);
  const Classified c = classify_view(view, iso);
  const int64_t x0 = c.lo[0];

  auto edges = [&](const Box3& box, bool quads) {
    return per_row(box, [&](int64_t j, int64_t k) {
      uint32_t n = 0;
      const int64_t lo = box.lo[0] - x0, hi = box.hi[0] - x0;
      for (int64_t w = lo >> 6; w <= (hi - 1) >> 6; ++w) {
        uint64_t m[3];
        edge_masks(c, j, k, w, quads, m);
        const uint64_t in = range_bits(w, lo, hi);
        for (uint64_t x : m) n += static_cast<uint32_t>(std::popcount(x & in));
      }
      return n;
    });
  };
  // Mixed cells of cell row (j, k): each contributes `weight(case, x, j, k)`.
  auto cells = [&](const Box3& box, auto&& weight) {
    return per_row(box, [&](int64_t j, int64_t k) {
      const uint64_t* rows[4] = {c.row(j, k), c.row(j + 1, k), c.row(j, k + 1),
                                 c.row(j + 1, k + 1)};
      uint32_t n = 0;
      const int64_t lo = box.lo[0] - x0, hi = box.hi[0] - x0;
      for (int64_t w = lo >> 6; w <= (hi - 1) >> 6; ++w) {
        const CellWord cw(rows, w, c.grid.words, c.grid.nx);
        for (uint64_t m = cw.mixed & range_bits(w, lo, hi); m; m &= m - 1) {
          const int b = std::countr_zero(m);
          n += weight(cw.cell_case(b), x0 + w * 64 + b, j, k);
        }
      }
      return n;
    });
  };

  BrickCounts out;
  if (layout == SiteLayout::EdgeVertices) {
    out.vertices = edges(vertex_box, false);
    out.faces = cells(face_box, [](int cs, int64_t, int64_t, int64_t) {
      return uint32_t{mc::kCaseTable.triangle_count[cs]};
    });
  } else {
    const bool patches = layout == SiteLayout::PatchVertices;
    out.vertices = cells(vertex_box, [&](int cs, int64_t x, int64_t y, int64_t z) {
      return static_cast<uint32_t>(cell_vertex_count(c, x, y, z, cs, patches));
    });
    out.faces = edges(face_box, true);
  }
  return out;
}

std::vector<std::uint8_t> upper_x_edge_vertices(const VolumeView& view, double iso,
                                                const Box3& cells) {
  const int64_t ny = cells.extent(1) + 1, nz = cells.extent(2) + 1;
  std::vector<std::uint8_t> out(static_cast<size_t>(ny * nz), 0);
  const Index3& n = view.global_dims;
  const int64_t x = cells.hi[0];
  if (x + 1 >= n[0]) return out;
  Box3 points = cells;
  points.lo[0] = x;
  require(view, points, 1);
  visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    const InsideTest<T> inside(iso);
    const T* data = view.typed<T>();
    const auto in = [&](int64_t i, int64_t j, int64_t k) {
      return inside(data[view.offset(i - view.box.lo[0], j - view.box.lo[1], k - view.box.lo[2])]);
    };
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, ny * nz), [&](const auto& range) {
      for (int64_t r = range.begin(); r != range.end(); ++r) {
        const int64_t y = cells.lo[1] + r % ny, z = cells.lo[2] + r / ny;
        const bool s = in(x, y, z);
        const int count = (s != in(x + 1, y, z)) + (y + 1 < n[1] && s != in(x, y + 1, z)) +
                          (z + 1 < n[2] && s != in(x, y, z + 1));
        out[static_cast<size_t>(r)] = static_cast<std::uint8_t>(count);
      }
    });
  });
  return out;
}

std::vector<uint64_t> brick_vertex_keys(const VolumeView& view, double iso, SiteLayout layout,
                                        const Box3& cells) {
  if (layout == SiteLayout::EdgeVertices) {
    MarchingCubesOptions o;
    o.iso = iso;
    o.cells = cells;
    return marching_cubes_vertex_keys(view, o);
  }
  // Active cells in [cells.lo - 1, cells.hi), clipped to the volume, one key per patch.
  Box3 box;
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = std::max<int64_t>(cells.lo[a] - 1, 0);
    box.hi[a] = std::min<int64_t>(cells.hi[a], view.global_dims[a] - 1);
  }
  const bool patches = layout == SiteLayout::PatchVertices;
  Box3 wider = box;
  for (int a = 0; a < 3; ++a) wider.lo[a] = std::max<int64_t>(wider.lo[a] - patches, 0);
  require(view, wider, 1 + patches);
  const Classified c = classify_view(view, iso);
  // Visits the active cells of global cell row (j, k) in the box: fn(x index, patch count).
  auto each_cell = [&](int64_t j, int64_t k, auto&& fn) {
    const uint64_t* rows[4] = {c.row(j, k), c.row(j + 1, k), c.row(j, k + 1), c.row(j + 1, k + 1)};
    const int64_t lo = box.lo[0] - c.lo[0], hi = box.hi[0] - c.lo[0];
    for (int64_t w = lo >> 6; w <= (hi - 1) >> 6; ++w) {
      const CellWord cw(rows, w, c.grid.words, c.grid.nx);
      for (uint64_t m = cw.mixed & range_bits(w, lo, hi); m; m &= m - 1) {
        const int b = std::countr_zero(m);
        const int64_t x = c.lo[0] + w * 64 + b;
        fn(x - c.lo[0], cell_vertex_count(c, x, j, k, cw.cell_case(b), patches));
      }
    }
  };
  const RowCounts counts = per_row(box, [&](int64_t j, int64_t k) {
    uint32_t n = 0;
    each_cell(j, k, [&](int64_t, int p) { n += static_cast<uint32_t>(p); });
    return n;
  });
  std::vector<uint64_t> offset(counts.count.size() + 1);
  for (size_t r = 0; r < counts.count.size(); ++r) offset[r + 1] = offset[r] + counts.count[r];
  std::vector<uint64_t> keys(offset.back());
  const int64_t ny = box.extent(1);
  tbb::parallel_for(
      tbb::blocked_range<int64_t>(0, static_cast<int64_t>(counts.count.size())),
      [&](const auto& range) {
        for (int64_t r = range.begin(); r != range.end(); ++r) {
          const int64_t j = box.lo[1] + r % ny, k = box.lo[2] + r / ny;
          const uint64_t base = static_cast<uint64_t>(c.n[0] * (j + c.n[1] * k) + c.lo[0]);
          uint64_t* out = keys.data() + offset[r];
          each_cell(j, k, [&](int64_t x, int p) {
            for (int q = 0; q < p; ++q)
              *out++ = 4 * (base + static_cast<uint64_t>(x)) + static_cast<uint64_t>(q);
          });
        }
      });
  return keys;
}

}  // namespace isotile
