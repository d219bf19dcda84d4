// How far a mesh's vertices lie from the exact surface of a procedural field: the `--stats` keys
// distance_mean and distance_max of `isotile extract field:NAME:N`.
#pragma once

#include "core/mesh/mesh.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume.h"

namespace isotile {

struct FieldDistance {
  double mean = 0, max = 0;  // voxels; 0 for a mesh without vertices
};

// Mean and largest distance_voxels() of the vertices of `mesh`, whose positions are origin +
// spacing x (voxel coordinates). Sums are taken per fixed chunk and added in chunk order, so the
// result does not depend on the thread count.
FieldDistance field_distance(const FieldSpec& spec, const Mesh& mesh, const Vec3d& origin,
                             const Vec3d& spacing);

}  // namespace isotile
