// Topological measures of a mesh: boundary and non-manifold edges and vertices, Euler
// characteristic, connected components.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>

#include "core/mesh/mesh.h"

namespace isotile {

struct TopologyOptions {
  // World-space box of the volume the mesh came from (min and max corner, as floats computed the
  // way extractors compute positions). Boundary edges whose two ends lie on the same face of this
  // box count as border edges: an isosurface legitimately ends there.
  std::optional<std::array<Vec3f, 2>> border_box = std::nullopt;
  // The inner faces of the border layer, for meshes whose open surfaces end inside the volume:
  // a boundary edge whose two ends lie between a face of border_box and the same face of this box
  // counts as a border edge. Unset: the ends must lie on the face. Dual Contouring's vertices
  // where a surface leaves the volume lie in the border cells, one voxel deep (border_layer()).
  std::optional<std::array<Vec3f, 2>> border_inner = std::nullopt;
  // Faces per chunk of the measure's local pass (0: its default). The results do not depend on
  // it; tests make it small so that many vertices have their faces in several chunks.
  std::size_t chunk_faces = 0;
};

struct TopologyStats {
  std::uint64_t vertices = 0;  // referenced by at least one face
  std::uint64_t unreferenced_vertices = 0;
  std::uint64_t edges = 0;
  std::uint64_t faces = 0;                  // triangles + quads
  std::uint64_t boundary_edges = 0;         // edges with exactly one face (border ones included)
  std::uint64_t border_boundary_edges = 0;  // of those, the ones lying on the volume border
  std::uint64_t nonmanifold_edges = 0;      // edges with more than two faces
  std::uint64_t nonmanifold_vertices = 0;   // faces around the vertex form more than one fan
  std::uint64_t inconsistently_oriented_edges = 0;  // manifold edges used twice in one direction
  std::int64_t euler = 0;                           // V - E + F over referenced vertices
  std::uint64_t components = 0;                     // connected by shared vertices
  bool closed = false;                              // no boundary edges and no non-manifold edges
  // The only boundary edges lie on the volume border (within border_inner), none non-manifold.
  // Without a border_box nothing is border: then the same as closed.
  bool watertight = false;
};

TopologyStats mesh_topology(const Mesh& mesh, const TopologyOptions& options = {});

}  // namespace isotile
