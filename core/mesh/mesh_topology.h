// Topological measures of a mesh: boundary and non-manifold edges and vertices, Euler
// characteristic, connected components.
#pragma once

#include <array>
#include <cstdint>
#include <optional>

#include "core/mesh/mesh.h"

namespace isotile {

struct TopologyOptions {
  // World-space box of the volume the mesh came from (min and max corner, as floats computed the
  // way extractors compute positions). Boundary edges whose two ends lie on the same face of this
  // box count as border edges: an isosurface legitimately ends there.
  std::optional<std::array<Vec3f, 2>> border_box;
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
  bool watertight = false;  // the only boundary edges lie on the volume border, none non-manifold
};

TopologyStats mesh_topology(const Mesh& mesh, const TopologyOptions& options = {});

}  // namespace isotile
