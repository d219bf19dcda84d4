// Self-intersecting triangle pairs of a mesh: users print, simulate and volume-mesh these surfaces,
// and a surface that passes through itself breaks all three.
//
// Definition. Vertices are identified by position (vertices with bit-equal coordinates are one
// vertex, whatever their indices), so a mesh with duplicated vertices is judged by its geometry.
// A triangle whose corners are collinear or coincide (zero area) is skipped: the quality measure
// counts those as degenerate. Two triangles intersect when they share a point other than the
// vertices and edges they have in common:
//   * no common vertex: any common point (touching at a point counts: a vertex lying on another
//     triangle, an edge grazing an edge, coplanar overlap);
//   * one common vertex v: any common point other than v (an opposite edge piercing the other
//     triangle, or, when an edge through v lies in the other triangle's plane, the two triangles
//     overlapping in a wedge at v);
//   * a common edge: only when the two are coplanar and fold onto each other (their third vertices
//     lie strictly on the same side of the edge); otherwise they meet exactly along the edge;
//   * three common vertices: always (a duplicated triangle).
// The predicates are CGAL's exact ones (filtered interval arithmetic with an exact fallback) on
// the float coordinates, so the answer does not depend on rounding: neighbours sharing an edge or
// a vertex are never false positives, and touching is decided exactly.
//
// A quad counts as its triangles (0, 1, 2) and (0, 2, 3).
//
// Broad phase: a uniform grid over triangle bounding boxes (count, sort, scan); each candidate
// pair is tested once, in the cell holding the low corner of the intersection of its two boxes.
// TBB-parallel; the result does not depend on the number of threads.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "core/mesh/mesh.h"

namespace isotile {

struct SelfIntersectionOptions {
  // Also return the intersecting pairs (sorted), up to this many; 0: count only.
  std::size_t max_pairs = 0;
};

struct SelfIntersections {
  std::uint64_t pairs = 0;    // intersecting triangle pairs
  std::uint64_t skipped = 0;  // zero-area triangles left out of the test
  // Face indices into the mesh's triangles, then its quads' triangles (quad q: triangles
  // 2q and 2q + 1 after mesh.triangles); first < second; ascending.
  std::vector<std::array<std::uint64_t, 2>> examples;
};

// Throws InputError when a face references a vertex past the end of positions or a position is
// not finite.
SelfIntersections self_intersections(const Mesh& mesh, const SelfIntersectionOptions& options = {});

// True when the triangle's corners are not collinear (exactly, on the float coordinates): the
// triangles the rule above applies to.
bool triangle_has_area(const std::array<Vec3f, 3>& t);

// The narrow-phase rule above for one pair of triangles given by corner positions and vertex
// identities (equal ids mean the same vertex; ids must be equal exactly when positions are).
// Exposed for tests. Both triangles must have non-zero area.
bool triangles_intersect(const std::array<Vec3f, 3>& a, const std::array<std::uint32_t, 3>& ia,
                         const std::array<Vec3f, 3>& b, const std::array<std::uint32_t, 3>& ib);

}  // namespace isotile
