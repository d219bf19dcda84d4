// The mesh every extractor returns: plain arrays, no behaviour.
//
// Triangles are wound so their normal (right-hand rule) points out of the region where the field
// is at or above the isovalue ("inside"), i.e. down the gradient: outward for CT data, where
// material is bright. In-memory meshes index vertices with uint32; an extraction that would need
// more vertices throws CapacityError (the streaming writer of the tiler is the way past that).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace isotile {

using Vec3f = std::array<float, 3>;
using Tri = std::array<std::uint32_t, 3>;
using Quad = std::array<std::uint32_t, 4>;

struct Mesh {
  std::vector<Vec3f> positions;  // world coordinates
  std::vector<Vec3f> normals;    // empty, or one unit normal per position
  std::vector<Tri> triangles;
  std::vector<Quad> quads;  // Dual Contouring may keep quads; most meshes have none
};

// Throws InputError naming the first triangle or quad that references a vertex past the end of
// positions. Readers, writers and measures call it before trusting indices from outside.
void check_face_indices(const Mesh& mesh);

}  // namespace isotile
