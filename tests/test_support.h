// Helpers shared by the extractor test suites.
#pragma once

#include <algorithm>
#include <filesystem>

#include "core/mesh.h"
#include "core/procedural_fields.h"

namespace isotile::testing {

// A real volume from ../shared/data (may not exist: callers skip with a message).
inline std::filesystem::path shared_volume(const char* name) {
  return std::filesystem::path(ISOTILE_SHARED_DATA) / name;
}

// Largest distance, in voxels, from a vertex of `m` to the field's exact surface.
inline double max_distance(const FieldSpec& spec, const Mesh& m) {
  double worst = 0;
  for (const Vec3f& p : m.positions)
    worst = std::max(worst, distance_voxels(spec, {p[0], p[1], p[2]}));
  return worst;
}

}  // namespace isotile::testing
