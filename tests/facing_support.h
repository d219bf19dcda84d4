// Whether a simplified mesh faces as its input does: for the simplify tests (kept out of
// test_support.h so that only they compile CGAL's tree).
#pragma once

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/mesh/mesh.h"

namespace isotile::testing {

// The smallest cosine between a face of `out` and the input surface beside it: the normal of the
// input face nearest to the face's centroid (CGAL's AABB tree, as core's surface_distance finds
// closest points). Faces below a thousandth of the input's mean area (the specks Marching Cubes
// makes around samples equal to the isovalue) have no meaningful normal and are passed over, in
// both meshes. Below 0, a face of `out` is turned over against the surface it stands for.
inline double worst_facing(const Mesh& in, const Mesh& out) {
  using K = CGAL::Simple_cartesian<double>;
  using Triangle = K::Triangle_3;
  using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<Triangle>::const_iterator>;
  using Tree = CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>>;
  const auto triangle = [](const Mesh& m, const Tri& t) {
    const auto p = [&](int i) {
      const Vec3f& v = m.positions[t[i]];
      return K::Point_3(v[0], v[1], v[2]);
    };
    return Triangle(p(0), p(1), p(2));
  };
  const auto area = [](const Triangle& t) { return std::sqrt(t.squared_area()); };
  double mean_area = 0;
  for (const Tri& t : in.triangles) mean_area += area(triangle(in, t));
  mean_area /= static_cast<double>(std::max<std::size_t>(in.triangles.size(), 1));
  std::vector<Triangle> faces;
  for (const Tri& t : in.triangles)
    if (const Triangle f = triangle(in, t); area(f) >= 1e-3 * mean_area) faces.push_back(f);
  Tree tree(faces.begin(), faces.end());
  tree.accelerate_distance_queries();
  double worst = 1;
  for (const Tri& t : out.triangles) {
    const Triangle f = triangle(out, t);
    if (area(f) < 1e-3 * mean_area) continue;
    const K::Point_3 c = CGAL::centroid(f);
    const Triangle& near = *tree.closest_point_and_primitive(c).second;
    const K::Vector_3 a = CGAL::normal(f[0], f[1], f[2]),
                      b = CGAL::normal(near[0], near[1], near[2]);
    worst = std::min(worst, (a * b) / std::sqrt(a.squared_length() * b.squared_length()));
  }
  return worst;
}

}  // namespace isotile::testing
