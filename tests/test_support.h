// Helpers shared by the extractor test suites.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <vector>

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

// Every run is byte-identical to the first (positions, normals, triangles, quads): the
// determinism contract across thread counts.
inline void expect_identical_runs(const std::vector<Mesh>& runs) {
  for (std::size_t i = 1; i < runs.size(); ++i) {
    EXPECT_EQ(runs[i].positions, runs[0].positions) << "run " << i;
    EXPECT_EQ(runs[i].normals, runs[0].normals) << "run " << i;
    EXPECT_EQ(runs[i].triangles, runs[0].triangles) << "run " << i;
    EXPECT_EQ(runs[i].quads, runs[0].quads) << "run " << i;
  }
}

}  // namespace isotile::testing
