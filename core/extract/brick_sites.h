// What an extraction of one brick will emit, known from the classification alone: per-row counts
// of the vertices and faces a brick owns, and the keys of the vertices a brick lists. The tiler's
// first pass uses the counts to give every vertex and face its final index before any is placed;
// the second pass uses the keys to turn a brick's local indices into those final indices.
//
// The brick contract (core/extract/marching_cubes.h, core/extract/dual_contouring.h): Marching
// Cubes and Macet put vertices on crossed edges, owned by the edge's lower sample, and faces in
// cells; Dual Contouring puts vertices in active cells and faces on crossed edges whose four cells
// exist. Keys are global: lin(s) * 3 + axis for an edge, lin(c) * 4 + patch for a cell's vertex
// (patch 0 when a cell has one), with lin(p) = p.x + N.x * (p.y + N.y * p.z) over the global
// sample dims N.
#pragma once

#include <cstdint>
#include <vector>

#include "core/volume/volume.h"

namespace isotile {

// Where a method's vertices and faces live.
enum class SiteLayout {
  EdgeVertices,   // Marching Cubes, Macet: vertices on edges (sample sites), faces in cells
  CellVertices,   // Dual Contouring (DcVertices::Cell): a vertex per active cell, faces on edges
  PatchVertices,  // Dual Contouring (DcVertices::Patch): a vertex per patch of an active cell
};

// The three keys per site of edge vertices, four (patches) of cell vertices.
inline std::uint64_t keys_per_site(SiteLayout layout) {
  return layout == SiteLayout::EdgeVertices ? 3 : 4;
}

// One count per row (y, z) of `box` (global indices), z-major: row r is (box.lo.y + r % ny,
// box.lo.z + r / ny), counting the sites with x in [box.lo.x, box.hi.x).
struct RowCounts {
  Box3 box;
  std::vector<std::uint32_t> count;
};

// Vertices owned by the sites in `vertex_box` (samples for EdgeVertices, cells for CellVertices)
// and faces of the sites in `face_box` (cells for EdgeVertices: triangles; samples for Cell- and
// PatchVertices: quads, one per crossed edge whose four cells exist). The view must hold every
// sample these depend on (one beyond each box); InputError otherwise.
struct BrickCounts {
  RowCounts vertices;
  RowCounts faces;
};
BrickCounts count_brick_sites(const VolumeView& view, double iso, SiteLayout layout,
                              const Box3& vertex_box, const Box3& face_box);

// EdgeVertices: per point row (y, z) of the closed box [cells.lo, cells.hi] (z-major, as
// RowCounts), the crossed edges owned by the sample at x = cells.hi.x, 0 to 3; all 0 when that is
// the volume's last sample plane (the brick owns it). A brick lists, per point row, the vertices
// its own column owns and then these, which open the next column's row. The view must hold the
// samples one beyond the box.
std::vector<std::uint8_t> upper_x_edge_vertices(const VolumeView& view, double iso,
                                                const Box3& cells);

// Keys of the vertices a brick-mode extraction of `cells` lists, in its order. The view must hold
// the samples the extractor's halo asks for.
std::vector<std::uint64_t> brick_vertex_keys(const VolumeView& view, double iso, SiteLayout layout,
                                             const Box3& cells);

}  // namespace isotile
