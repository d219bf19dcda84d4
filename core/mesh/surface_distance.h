// Two-way sampled distance between two surfaces (a sampled Hausdorff distance): how far a
// simplified mesh strays from its input, and the input from it.
//
// Each direction samples one mesh and finds, for every sample, the closest point on the other
// mesh's faces (CGAL's AABB trees, exact closest points in double; a face of no area whose
// corners lie on a line counts as that line). The samples of a mesh are the vertices of its faces
// (but for faces whose corners meet at one point) plus area-weighted points on its faces:
// `face_samples` points placed by
// systematic sampling along the cumulative area (evenly spaced in area, each at a fixed
// quasi-random spot inside its triangle), so the result is deterministic and independent of the
// thread count. The vertices catch the far tips that uniform sampling of the faces would miss.
//
// Distances are measured after scaling coordinates by `scale` per axis: pass 1/spacing to get
// them in voxels for a mesh extracted from a volume.
#pragma once

#include <cstdint>
#include <optional>

#include "core/mesh/mesh.h"
#include "core/volume/volume.h"

namespace isotile {

struct SurfaceDistanceOptions {
  std::uint64_t face_samples = 200000;  // per direction, besides the vertices
  Vec3d scale{1, 1, 1};
};

struct OneWayDistance {
  double mean = 0, max = 0;
  Vec3d max_at{0, 0, 0};  // the sample farthest from the other mesh (scaled coordinates)
  std::uint64_t samples = 0;
};

struct SurfaceDistance {
  OneWayDistance a_to_b, b_to_a;
  double max() const { return a_to_b.max > b_to_a.max ? a_to_b.max : b_to_a.max; }
  // The mean of the two directions' means.
  double mean() const { return 0.5 * (a_to_b.mean + b_to_a.mean); }
};

// Quads count as two triangles. Nothing where either mesh has no face of non-zero area: the
// distance is undefined there (the stats say null).
std::optional<SurfaceDistance> surface_distance(const Mesh& a, const Mesh& b,
                                                const SurfaceDistanceOptions& options = {});

}  // namespace isotile
