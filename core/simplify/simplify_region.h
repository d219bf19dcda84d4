// The simplification kernel: edge collapses on one region of a mesh, with some vertices locked.
//
// The driver (core/simplify/simplify.cpp) cuts a mesh into regions and runs one RegionSimplifier
// per region, in parallel; the vertices a region shares with others, the mesh's boundary vertices
// and the copies made to pass non-manifold input are locked: they neither move nor disappear, so
// regions fit back together exactly. A region's work is sequential and deterministic.
//
// With an error bound, every change (collapse, flip, move) is checked against points of the input
// surface: each is attached to a face, and a change must leave every point of the faces it
// replaces within the bound of one of the faces that replace them (it is then attached there).
// So every input vertex and face centroid stays within the bound of the result, and every result
// vertex within the bound of the planes it stands for.
//
// Algorithm (on an OpenMesh triangle mesh; OpenMesh's link-condition check decides which
// collapses keep the surface a manifold of the same topology):
//   1. Collapse. An indexed heap orders edges by the plane-quadric error of their best position
//      (Garland-Heckbert, every input plane with weight 1, placement regularised toward the
//      edge's midpoint so that flat regions stay evenly spread) plus a term in the edge's squared
//      length (short edges first where error ties, which keeps triangles round). An edge is
//      checked only when it reaches the top of the heap: topology (OpenMesh's is_collapse_ok; no
//      new edge between two locked vertices, which another region could make too; copies of one
//      split vertex never neighbours), normals (no face turns by more than the allowed angle in
//      one change, nor ends up facing further than 90 degrees from the input surface its corners
//      stand for: the area vectors their quadrics carry, summed) and shape (no new triangle below
//      the quality floor unless the collapse lifts the worst triangle around it). A refused edge
//      waits outside the heap until its neighbourhood changes.
//      The driver calls collapse() in rounds with a cost ceiling common to all regions, so that
//      the regions together collapse in nearly the order one heap over the whole mesh would.
//   2. Shape (finish()). Edge flips where nearly coplanar triangles get a better worst triangle,
//      then tangential relaxation: each vertex moves toward the centroid of its neighbours within
//      its tangent plane, then back along the normal to its quadric's minimum, so it stays on the
//      planes it represents. Moves and flips that would lower the worst triangle around them,
//      turn a face (either check above), or stray too far from the planes are refused.
//   3. Cleanup (finish()). Each triangle still below the quality floor gets, in turn, a flip of
//      one of its edges, a collapse of its shortest edge, or a small move of its corners (a
//      pattern search for the position that lifts the worst triangle around the corner, within a
//      fifth of the corner's mean edge length): thin tubes and specks that topology forbids to
//      collapse are widened just enough.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/simplify/quadric.h"
#include "core/volume/volume.h"

namespace isotile {

struct RegionOptions {
  double max_error = 0;            // > 0: no vertex strays further from its planes
  double min_quality = 0.3;        // radius-ratio floor for new triangles and the cleanup
  double max_normal_turn = 0.5;    // cosine: no change may turn a face by more than this angle
  double max_input_turn = 0.0;     // cosine: no face may face further than this angle from the
                                   // input surface its corners stand for (their area vectors)
  double input_coherence = 0.5;    // ... where those face this coherently: |sum| / sum of areas
  double input_slack = 1e-4;       // ... but for this share of their area (specks)
  double length_weight = 0.05;     // weight of the squared edge length in the cost
  double placement_pull = 0.02;    // regularisation of the optimal position toward the midpoint
  int relax_passes = 3;            // 0: no flips and no relaxation
  double relax_tolerance = 0.01;   // relaxation may add this times the squared mean edge
                                   // length to a vertex's mean squared plane distance
  double flip_max_angle = 0.9848;  // cosine (10 degrees): flips only between near-coplanar faces
  double cleanup_reach = 0.2;      // cleanup moves: at most this times the mean edge length
};

struct Region {
  std::vector<Vec3d> positions;
  std::vector<Quadric> quadrics;     // per vertex (the planes of the input faces it stands for)
  std::vector<std::uint8_t> locked;  // 1: neither moves nor goes
  std::vector<std::int32_t> group;   // empty, or per vertex: copies of one input vertex share a
                                     // group >= 0 (never neighbours); -1 elsewhere
  std::vector<std::uint32_t> id;     // the caller's identity of each vertex, handed back
  std::vector<Tri> triangles;
  // With an error bound: points of the input surface (its vertices and face centroids), each
  // with the index of the face it is attached to, which it must stay within max_error of.
  std::vector<Vec3d> points;
  std::vector<std::uint32_t> point_face;
};

struct RegionStats {
  std::uint64_t collapses = 0, flips = 0, relaxed = 0, cleanup = 0;
  std::uint64_t refused_topology = 0, refused_shape = 0, refused_normal = 0, refused_error = 0;
  std::uint64_t unlinked_faces = 0;  // faces OpenMesh could not link, passed through unchanged
};

class RegionSimplifier {
 public:
  RegionSimplifier(Region region, const RegionOptions& options);
  ~RegionSimplifier();
  RegionSimplifier(RegionSimplifier&&) noexcept;
  RegionSimplifier& operator=(RegionSimplifier&&) noexcept;

  std::uint64_t faces() const;
  // Appends the heap keys of the edges waiting to collapse.
  void costs(std::vector<double>& out) const;
  // Collapses the cheapest edges while their key is at most `max_cost` and fewer than
  // `max_collapses` have been made in this call. Returns the number made.
  // `progress`: checked for cancel every 1024 edges taken off the heap (Cancelled).
  std::uint64_t collapse(double max_cost, std::uint64_t max_collapses,
                         const Progress* progress = nullptr);
  // Flips, relaxation and cleanup; then hands back the surviving vertices (with their caller
  // ids, moved positions and accumulated quadrics) and faces.
  Region finish();
  const RegionStats& stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotile
