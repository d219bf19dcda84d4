// Simplification of a triangle mesh by edge collapses that keep its shape, its topology, its
// border and the good triangles extraction made.
//
// The mesh is cut into regions by a grid over its bounding box (about kRegionFaces faces each;
// the grid depends on the mesh only, never on the thread count) and each region is simplified on
// its own thread (core/simplify/simplify_region.h) with the vertices it shares with other regions
// locked. A second pass does the same on a grid shifted by half a cell, whose regions straddle the
// first pass's seams and finish them. So the result is deterministic for any thread count.
//
// What is kept:
//   * topology: collapses pass OpenMesh's link-condition check, so no non-manifold edge is
//     created and closed components stay closed (a component stops shrinking at a tetrahedron);
//   * the boundary: vertices on boundary edges never move or go, so boundary edges (a volume's
//     border among them) stay exactly where they were and neighbouring tiles still meet;
//   * non-manifold input (Dual Contouring's one-vertex-per-cell meshes): every vertex whose faces
//     form several fans, or that lies on an edge with more than two faces or with faces of
//     opposite orientation, is split into one locked copy per fan for the collapses and welded
//     back afterwards, so no face is dropped and nothing new becomes non-manifold;
//   * orientation: no change leaves a face facing further than 90 degrees from the input surface
//     its corners stand for (each vertex's quadric carries those faces' area vectors), unless it
//     already did and turns no further, or is a speck (Marching Cubes makes zero-area faces and
//     specks where samples equal the isovalue; see simplify_region.h);
//   * shape: a radius-ratio floor on new triangles, then flips, tangential relaxation and a
//     cleanup of what is still below the floor (see simplify_region.h).
//
// Quads are split first along their better diagonal; the result has triangles only. When the
// input has normals, the result gets area-weighted vertex normals.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/simplify/quadric.h"

namespace isotile {

struct SimplifyOptions {
  // Stop at the first of these that is reached: the face count (`faces` if non-zero, else `ratio`
  // of the input's faces if non-zero), and, with max_error > 0, the error bound. At least one
  // must be set.
  double ratio = 0;
  std::uint64_t faces = 0;
  // Mesh units. Every input vertex, edge midpoint and face centroid stays within this of the
  // result, and every result vertex within this of each plane of the input faces it stands for
  // (its quadric's sum of squared distances stays within max_error^2). Between those points the
  // input may stray slightly further where max_error is below a third of its edge length.
  double max_error = 0;
  // Radius ratio below which a collapse may not take a new triangle (unless it lifts the worst
  // triangle around it) and the cleanup pass works.
  double min_quality = 0.3;
  bool relax = true;  // flips and tangential relaxation after the collapses
  // Called as regions complete, with the pass ("collapse", "seams") and counts.
  // Told of regions as they complete (Stage::Simplify, one unit per region, per pass); null:
  // nobody listens. Cancelling throws Cancelled.
  Progress* progress = nullptr;
};

struct SimplifyStats {
  std::uint64_t faces_before = 0, faces_after = 0;
  std::uint64_t vertices_before = 0, vertices_after = 0;  // referenced by faces
  std::uint64_t target_faces = 0;                         // 0: error bound only
  std::int64_t regions = 0, seam_regions = 0;
  std::uint64_t boundary_vertices = 0;  // locked because they lie on a boundary edge
  // Non-manifold input: vertices split into copies (one per fan) and the copies made; faces
  // OpenMesh still could not link (passed through unchanged).
  std::uint64_t split_vertices = 0, split_copies = 0, unlinked_faces = 0;
  std::uint64_t collapses = 0, flips = 0, relaxed = 0, cleanup = 0;
};

// A warning where the result holds more than a tenth more faces than its target (the checks
// that keep topology, the border, orientation and shape refused the collapses left: thin parts,
// a long border, and out of core the bricks' seams hold faces), or more than a tenth fewer (the
// cleanup's collapses below a raised quality floor); empty otherwise.
std::string target_missed(const SimplifyStats& stats);

// Throws InputError for options without a target, a ratio outside (0, 1], or invalid face
// indices.
Mesh simplify(const Mesh& mesh, const SimplifyOptions& options, SimplifyStats* stats = nullptr);

// Piece by piece, for meshes that are never whole in memory (the out-of-core tiler). A piece's
// boundary vertices are locked (its boundary is where it meets other pieces, or the mesh's own
// border), vertices keep the caller's keys, and each carries its quadric, so that a later pass
// over pieces joined at their seams (vertices with equal keys) goes on where this one stopped.
struct MeshPiece {
  std::vector<Vec3d> positions;
  std::vector<Quadric> quadrics;    // per vertex; empty: computed from the faces
  std::vector<std::uint64_t> keys;  // per vertex: the caller's identity, handed back
  std::vector<Tri> triangles;
};

// Simplifies toward `target_faces` (0: only options.max_error stops it; options.ratio and
// options.faces are not used). With `boundary_allowance`, it stops short of the target by what
// its locked boundary is expected to hold (about 4 faces per boundary vertex, scaled by the
// reduction), for a later pass over the seams to take. Adds to *stats. Throws InputError for
// inconsistent arrays.
MeshPiece simplify_piece(MeshPiece piece, std::uint64_t target_faces,
                         const SimplifyOptions& options, SimplifyStats* stats = nullptr,
                         bool boundary_allowance = false);

}  // namespace isotile
