// Table-driven Dual Contouring on the CPU (paper Sec. III; table in dual_contouring_table.h).
//
// Classification is Marching Cubes': a sample is inside when value >= iso. Every cell (the cube
// between samples (i..i+1, j..j+1, k..k+1)) with a crossed edge among its 12 gets one dual vertex
// per surface patch (DcVertices::Patch, the default) or one in all (DcVertices::Cell), placed from
// the Hermite data of the patch's (or cell's) edges: their crossings (linear interpolation from
// each edge's lower-index end, as in MC) and unit normals there (central-difference gradients of
// the samples, one-sided only at the border of the whole volume, interpolated along the edge).
// Every crossed edge whose four surrounding cells all exist gets one quad joining the vertices that
// serve it in those cells, wound so its normal points from the inside end of the edge to the
// outside end. Edges on the border of the volume lack some of those cells and get no quad: the
// mesh is open there, like MC's. A cell whose only crossed edges lie on the border still gets its
// vertex, which no face then uses.
//
// Positions are origin + spacing * (global cell index + offset in the cell), computed in double
// and rounded to float, so bricks of one volume agree on the vertices they share.
//
// Parallel and deterministic: count, exclusive scan, fill over rows of cells and of samples.
// Order (the brick contract): vertices cell by cell in ascending global key 4 lin(cell) + patch,
// lin(cell) = x + Nx (y + Ny z) with the volume's sample dims N as strides (patch 0 alone with
// DcVertices::Cell); faces by the global index of their edge's
// lower sample, then axis x, y, z (the table lists a case's quads in that order). A split quad q
// becomes triangles 2q and 2q + 1. The output is byte-identical for any thread count.
//
// Brick mode (`cells` non-empty, global cell indices): the faces of the crossed edges (s, a) with
// s in the half-open box [cells.lo, cells.hi) whose four cells exist in the volume, and the
// vertices of every active cell in [cells.lo - 1, cells.hi) clipped to the volume, in key order.
// The view must hold those cells plus dual_contouring_halo() samples on every side (less where
// the volume ends; InputError otherwise). Every vertex is computed from the same samples with the
// same arithmetic as in a whole-volume run, so bricks agree bit for bit on shared vertices and
// their union (faces mapped through the keys) is the whole-volume mesh.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/volume/volume.h"

namespace isotile {

// How a dual vertex is placed in its cell.
//   Particle:  the paper's particle: from the mass point, x <- clamp(x + c F(x)), where F is the
//              trilinear interpolation of the corner forces F_k = sum_i (n_i . (P_i - V_k)) n_i.
//              F is affine, so this is projected gradient descent on Ju et al.'s QEF; few steps
//              stay near the mass point (smooth, well-shaped), many steps reach sharp features.
//   Qef:       Ju et al.'s QEF minimised by a truncated eigen decomposition (Jacobi sweeps,
//              dc::symmetric_eigen) about the mass point, then clamped to the cell.
//   MassPoint: the mean of the cell's crossings (SurfaceNets-like; best triangles, no features).
enum class DcSolver { Particle, Qef, MassPoint };

// Where the Hermite data (crossings, normals) come from.
//   Central: crossings by linear interpolation along the edge, normals from central-difference
//            gradients at the edge's ends interpolated to the crossing (the paper's choice).
//   Eno:     crossings and normals that respect sharp features: near a kink at or between an
//            edge's samples (two quadratic pieces, through the three samples beyond each end,
//            that miss the other end on the same side) the root is that of min or max of the
//            pieces, and the normal takes its piece's slope and its end's gradient; normals use
//            one-sided (ENO) differences where one side of a sample bends much less than the
//            other, or where both bend and only one side's edge holds a kink. With the QEF on
//            csg-box it cuts DC's worst vertex error to 0.030 / 0.020 / 0.019 / 0.012 voxel at
//            N = 32 / 50 / 64 / 128 (central: 0.18-0.27; MC: 0.20 / 0.20 / 0.13 / 0.22), under a
//            quarter of MC's; smooth fields change by at most 2% (docs/quality.md). Halo 4.
enum class DcHermite { Central, Eno };

// How many dual vertices a cell gets.
//   Patch: one per surface patch of the cell (the polygons Marching Cubes draws there; table in
//          dual_contouring_table.h), each placed from the Hermite planes of its own edges, as in
//          Dual Marching Cubes / Manifold Dual Contouring, with the face flips and border cuts
//          of dual_contouring_patches.h: every edge has at most two faces and every vertex one
//          fan (0 non-manifold edges and vertices on the shared volumes and on random ones).
//          Halo and cost are the cell variant's; patch vertices read the cases of the cells
//          across their faces, which the halo already holds.
//   Cell:  one per cell from all its planes (the paper's table). Where a cell holds several
//          sheets they meet in its one vertex: non-manifold edges (bonsai at 49.5: 4,095).
enum class DcVertices { Patch, Cell };

struct DualContouringOptions {
  double iso = 0.0;
  // The mass point by default. Measured at iso 49.5 (radius ratio min / mean): bonsai 0.015 /
  // 0.809 against particle-10 0.0002 / 0.806 and QEF 0 / 0.796; engine 0.012 / 0.836 against
  // 0.007 / 0.836 and 0.001 / 0.836. It is also the fastest: 1.6-1.8x MC's time against 3.4-4.1x
  // (particle-10) and 5-6x (QEF with a closed-form eigen solver; the Jacobi sweeps that replaced
  // it for the GL paths' sake give the same meshes about 1.3-2x slower). The Hermite solvers gain
  // accuracy, less than hoped at sharp features with the paper's Hermite data, which blur within a
  // voxel of a sharp edge: on csg-box (N = 64) they cut the worst vertex error from 0.27 to 0.21
  // voxels (MC: 0.13), to 0.019 with DcHermite::Eno. On smooth surfaces three particle steps cut
  // the mean error 5x, to MC's (sphere N = 64: 0.010 to 0.002 voxels).
  DcSolver solver = DcSolver::MassPoint;
  int particle_steps = 10;           // at most this many steps...
  double particle_rate = 0.05;       // c in x <- clamp(x + c F(x)); stable below 2 / 12
  double particle_tolerance = 1e-4;  // ...stopping once a step moves less than this (voxels)
  double qef_eigen_cutoff = 0.1;     // drop eigenvalues below this times the largest one
  bool keep_quads = false;  // true: Mesh::quads; false: two triangles per quad, split along the
                            // diagonal whose worse triangle has the better radius ratio
  bool normals = false;     // unit normals at the vertices, pointing outward
  DcHermite hermite = DcHermite::Central;
  DcVertices vertices = DcVertices::Patch;
  Box3 cells{};  // brick mode, in global cell indices; empty: every cell of the view
  // Told of the work's progress (Stage::Count, then Stage::Extract; core/progress.h), a z-slice of
  // rows at a time; null: nobody listens. Cancelling throws Cancelled.
  Progress* progress = nullptr;
};

// Samples beyond `cells` that brick mode reads: 2 (vertex cells reach one cell below the box, and
// gradients and the tie test of core/extract/isovalue_ties.h one sample beyond their corners), 4
// with DcHermite::Eno.
int dual_contouring_halo(const DualContouringOptions& options);

// Extracts the isosurface of the cells of `view`. Throws CapacityError when the mesh would need
// more than 2^32 - 1 vertices, InputError for a negative step count or a non-positive rate.
Mesh dual_contouring(const VolumeView& view, const DualContouringOptions& options);

// The keys 4 lin(cell) + patch (global, sample dims as strides) of the vertices
// dual_contouring(view, options) returns, in the same order.
std::vector<std::uint64_t> dual_contouring_vertex_keys(const VolumeView& view,
                                                       const DualContouringOptions& options);

// The local repairs DcVertices::Patch makes over the cells of `view` (dual_contouring_patches.h):
// ambiguous faces resolved the other way because both cells joined their two segments (each face
// counted once), and border cells whose patches were cut at the volume's border faces.
struct DcPatchRepairs {
  std::uint64_t flipped_faces = 0;
  std::uint64_t border_cut_cells = 0;
};
DcPatchRepairs dual_contouring_patch_repairs(const VolumeView& view, double iso);

namespace dc {

// One Hermite sample of a cell: a crossing p and the unit normal n there (zero where the gradient
// vanishes; such a plane constrains nothing). Coordinates are cell-local, in voxels: the cell is
// [0, 1]^3.
struct HermitePlane {
  std::array<double, 3> p;
  std::array<double, 3> n;
};

// The dual vertex of a cell with `count` >= 1 Hermite planes, in cell-local coordinates inside
// [0, 1]^3. This is the per-cell kernel every extraction path shares; the pieces below are its
// stages, exposed so a path can batch cells (the extractor runs particles eight cells abreast)
// and still get the same bits as this function.
std::array<double, 3> place_vertex(const HermitePlane* planes, int count,
                                   const DualContouringOptions& options);

// What the solvers need of a cell's planes: the mass point and the QEF's normal equations
// A x = b, A = sum n n^T, b = sum n (n . p) (left zero when `with_normals` is false).
struct CellQef {
  std::array<double, 3> mass;
  double a[3][3];
  double b[3];
};
CellQef accumulate(const HermitePlane* planes, int count, bool with_normals);
// DcSolver::Particle for n cells at once; out[i] is what place_vertex gives for cell i.
void run_particles(const CellQef* cells, int n, const DualContouringOptions& options,
                   std::array<double, 3>* out);
// DcSolver::Qef, over symmetric_eigen's decomposition of A.
std::array<double, 3> solve_qef(const CellQef& cell, const DualContouringOptions& options);

// The eigenvalues of a symmetric 3x3 matrix in ascending order and their unit eigenvectors, by
// at most kJacobiSweeps cyclic Jacobi sweeps: plain IEEE double arithmetic and sqrt, which the GL
// paths repeat step for step (a closed form would need acos and cos, which GLSL lacks in double).
inline constexpr int kJacobiSweeps = 6;
// A rotation for an off-diagonal element below this fraction of its diagonal changes the
// eigenvalues by less than their rounding; once a sweep finds none, the matrix is diagonal.
inline constexpr double kJacobiNegligible = 1e-18;
// ENO Hermite data: an edge is kinked where its two cubic pieces miss the far sample by errors of
// one sign, the larger above this fraction of the edge's rise (dual_contouring.cpp's Pieces).
inline constexpr double kEnoKink = 0.4;
struct SymmetricEigen {
  double value[3];
  double vector[3][3];  // vector[e]: the eigenvector of value[e]
};
SymmetricEigen symmetric_eigen(const double a[3][3]);

}  // namespace dc

}  // namespace isotile
