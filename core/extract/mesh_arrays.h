// Sizing an extracted triangle mesh's arrays before the parallel fill. Internal to core/.
#pragma once

#include <tbb/parallel_invoke.h>

#include <cstddef>

#include "core/extract/scratch_vector.h"
#include "core/mesh/mesh.h"

namespace isotile::detail {

// Resizes positions (and normals) and triangles. std::vector zeroes what it allocates, taking each
// page's first-touch fault as it goes: the vertex and the triangle arrays are zeroed side by side
// rather than one after the other, in blocks reserved on the calling thread (reserve_on_caller).
inline void size_mesh_arrays(Mesh& mesh, std::size_t vertices, std::size_t triangles,
                             bool normals) {
  reserve_on_caller(mesh.positions, vertices);
  if (normals) reserve_on_caller(mesh.normals, vertices);
  reserve_on_caller(mesh.triangles, triangles);
  tbb::parallel_invoke(
      [&] {
        mesh.positions.resize(vertices);
        if (normals) mesh.normals.resize(vertices);
      },
      [&] { mesh.triangles.resize(triangles); });
}

}  // namespace isotile::detail
