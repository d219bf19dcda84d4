// Triangles of a polygon read from a mesh file (OBJ, OFF and PLY faces of five or more corners).
//
// A fan from the first corner covers a convex polygon but folds over a concave one (an L, a
// letter's outline from a CAD export): triangles outside the polygon, overlapping others, which
// every measure, simplification and picture then takes for the surface. Ear clipping in the
// polygon's plane (its Newell normal) keeps every triangle inside. A convex polygon (every corner
// turning the same way) is still the fan, so meshes that were right stay the same bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/mesh/mesh.h"

namespace isotile {

// Writes the n - 2 triangles of the polygon `corners[0..n)` (indices into `positions`, n >= 3) to
// `out[0..n-2)`, wound as the polygon is. Where no ear is left (a polygon that crosses itself,
// folds onto a line or has no area), the rest is a fan from its first remaining corner: the same
// count, whatever the input.
void triangulate_polygon(const std::vector<Vec3f>& positions, const std::uint32_t* corners,
                         std::size_t n, Tri* out);

}  // namespace isotile
