// Macet: Marching Cubes with edge transformations (Dietrich et al., TVCG 2009), on the CPU.
//
// Topology is exactly Marching Cubes': samples are classified with value >= iso as inside, the
// crossed edges are MC's, and every crossed edge gets one vertex. Only where that vertex lies
// changes: each grid vertex at the end of a crossed edge is displaced first (once, shared by every
// cell and edge that uses it, so the mesh stays crack-free), then the vertex is the root of the
// trilinear interpolant on the segment between the two displaced end points. A displacement never
// moves a grid vertex across the surface (its interpolated value keeps its side), so every
// transformed edge still brackets a crossing. Triangles come from the Macet-derived case table
// (core/extract/macet_table.h): MC's polygons, triangulated so that fewer skinny triangles appear.
//
// Quality modes (docs/macet.md has the measurements behind them):
//   Fast: each grid vertex is pushed away from the crossings on its own edges that lie closer
//         than 0.4 of an edge, then moved once within its tangent plane by the mean mesh
//         Laplacian of those crossings (one smoothing pass through the end points).
//   Max:  Fast, then a local search per grid vertex on the worst triangles: Gauss-Seidel sweeps
//         over 27 colours of grid vertices (coordinates modulo 3: vertices of one colour cannot
//         affect each other, so they move in parallel and the result does not depend on the
//         thread count), guarded so that no move adds a self-intersecting pair.
//
// Output order and brick mode follow the brick contract (same as marching_cubes): vertices in
// ascending key lin(s) * 3 + axis over the closed cell box, triangles cell by cell in z, y, x and
// table order. The keys are marching_cubes_vertex_keys()'s for the same options.
#pragma once

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/volume/volume.h"

namespace isotile {

enum class MacetQuality { Fast, Max };

struct MacetOptions {
  double iso = 0.0;
  bool normals = false;  // unit normals from the interpolated central-difference gradient
  MacetQuality quality = MacetQuality::Fast;
  // Max only: Gauss-Seidel sweeps of the local search (each sweep visits all eight colours), in
  // [0, 100].
  int max_sweeps = 3;
  // Relaxation of sign-pinned samples (core/extract/macet_relax.h), in edge lengths, in [0, 0.5): 0
  // keeps every vertex on the volume's trilinear interpolant. A sample in a one-sample-thin
  // feature whose crossings on both sides of one axis lie closer than `relax` is moved away from
  // the isovalue (its side kept) until they lie `relax` away, moving none by more than `relax`.
  // The surface then moves by at most `relax` voxels next to such samples, and the slivers they
  // force go: bonsai's Max minimum 0.107 -> 0.46 at 0.35 (docs/macet.md).
  double relax = 0.0;
  // Brick mode, in global cell indices (empty: every cell of the view); the view must hold these
  // cells grown by macet_halo(options) samples on every side (less at the volume border).
  Box3 cells{};
  // Told of the work's progress (Stage::Count, then Stage::Extract; core/progress.h), a z-slice of
  // rows at a time; null: nobody listens. Cancelling throws Cancelled.
  Progress* progress = nullptr;
};

// Samples beyond the cells that brick mode reads: 3 for Fast; for Max 6 plus how far its colour
// steps can carry a change (48, 93, 138 for 1, 2, 3 sweeps; docs/macet.md); one more with relax
// (a relaxed sample depends on its neighbours). Throws as check_macet_options() does.
int macet_halo(const MacetOptions& options);

// Throws InputError for max_sweeps outside [0, 100] or a relax outside [0, 0.5), and CapacityError
// when the mesh would need more than 2^32 - 1 vertices.
Mesh macet(const VolumeView& view, const MacetOptions& options);

// InputError for options macet() refuses (max_sweeps outside [0, 100], relax outside [0, 0.5)); for
// other implementations of the method (the GL paths).
void check_macet_options(const MacetOptions& options);

}  // namespace isotile
