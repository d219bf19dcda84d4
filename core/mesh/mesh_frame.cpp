#include "core/mesh/mesh_frame.h"

#include <cmath>
#include <utility>

#include <tbb/parallel_for.h>

#include "core/errors.h"

namespace isotile {

namespace {

double det3(const Mat3& m) {
  return m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
         m[2] * (m[3] * m[7] - m[4] * m[6]);
}

}  // namespace

MeshFrame mesh_frame(const Vec3d& grid_origin, const std::optional<WorldFrame>& world) {
  MeshFrame f;
  if (!world) return f;
  f.grid_origin = grid_origin;
  f.world_origin = world->origin;
  f.direction = world->direction;
  f.active = world->origin != grid_origin || world->direction != kIdentity3;
  if (!f.active) return f;
  const Mat3& m = f.direction;
  const double det = det3(m);
  if (!std::isfinite(det) || std::abs(det) < 1e-12)
    throw InputError("the volume's direction cosines are singular (determinant " +
                     std::to_string(det) + ")");
  f.flip = det < 0;
  // Inverse transpose = cofactor matrix / det.
  f.normal_matrix = {(m[4] * m[8] - m[5] * m[7]) / det, -(m[3] * m[8] - m[5] * m[6]) / det,
                     (m[3] * m[7] - m[4] * m[6]) / det, -(m[1] * m[8] - m[2] * m[7]) / det,
                     (m[0] * m[8] - m[2] * m[6]) / det, -(m[0] * m[7] - m[1] * m[6]) / det,
                     (m[1] * m[5] - m[2] * m[4]) / det, -(m[0] * m[5] - m[2] * m[3]) / det,
                     (m[0] * m[4] - m[1] * m[3]) / det};
  return f;
}

Vec3f frame_position(const MeshFrame& f, const Vec3f& p) {
  if (!f.active) return p;
  const Vec3d d{static_cast<double>(p[0]) - f.grid_origin[0],
                static_cast<double>(p[1]) - f.grid_origin[1],
                static_cast<double>(p[2]) - f.grid_origin[2]};
  Vec3f out;
  for (int r = 0; r < 3; ++r)
    out[r] = static_cast<float>(f.world_origin[r] + f.direction[3 * r] * d[0] +
                                f.direction[3 * r + 1] * d[1] + f.direction[3 * r + 2] * d[2]);
  return out;
}

Vec3f frame_normal(const MeshFrame& f, const Vec3f& n) {
  if (!f.active) return n;
  Vec3d v;
  for (int r = 0; r < 3; ++r)
    v[r] = f.normal_matrix[3 * r] * n[0] + f.normal_matrix[3 * r + 1] * n[1] +
           f.normal_matrix[3 * r + 2] * n[2];
  const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (len > 0)
    for (double& c : v) c /= len;
  return {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
}

void apply_frame(const MeshFrame& f, Mesh& mesh) {
  if (!f.active) return;
  tbb::parallel_for(std::size_t{0}, mesh.positions.size(), [&](std::size_t i) {
    mesh.positions[i] = frame_position(f, mesh.positions[i]);
  });
  tbb::parallel_for(std::size_t{0}, mesh.normals.size(),
                    [&](std::size_t i) { mesh.normals[i] = frame_normal(f, mesh.normals[i]); });
  if (!f.flip) return;
  for (Tri& t : mesh.triangles) std::swap(t[1], t[2]);
  for (Quad& q : mesh.quads) std::swap(q[1], q[3]);
}

}  // namespace isotile
