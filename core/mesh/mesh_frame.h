// Mapping meshes from the grid frame the extractors work in (origin + spacing * index) into a
// volume's world frame (its direction cosines, ITK's LPS for medical images).
//
// The map is applied where positions are written (the CLI's writes, the tiler's streamed
// records, the MeshLab filter's mesh), one vertex at a time by the same function, so an in-core
// and a streamed run still write the same bytes. A direction with a negative determinant
// mirrors the mesh: faces are then written in reverse order so they still face out of the
// inside.
#pragma once

#include <optional>

#include "core/mesh/mesh.h"
#include "core/volume/volume.h"

namespace isotile {

struct MeshFrame {
  bool active = false;   // false: positions are written as extracted
  Vec3d grid_origin{};   // the volume's origin (grid frame)
  Vec3d world_origin{};  // WorldFrame::origin
  Mat3 direction = kIdentity3;
  Mat3 normal_matrix = kIdentity3;  // inverse transpose of direction (normals of sheared grids)
  bool flip = false;                // det(direction) < 0
};

// Inactive when `world` is unset or says the same as the grid frame. Throws InputError when
// the direction is singular.
MeshFrame mesh_frame(const Vec3d& grid_origin, const std::optional<WorldFrame>& world);
inline MeshFrame mesh_frame(const VolumeView& view) {
  return mesh_frame(view.origin, view.world);
}

Vec3f frame_position(const MeshFrame& f, const Vec3f& p);
Vec3f frame_normal(const MeshFrame& f, const Vec3f& n);

// Positions, normals and (when the frame mirrors) the winding of every face.
void apply_frame(const MeshFrame& f, Mesh& mesh);

}  // namespace isotile
