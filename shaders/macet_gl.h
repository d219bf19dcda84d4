// Macet (core/extract/macet.h) on the OpenGL paths: the geometry-shader and HistoPyramid drivers
// of Marching Cubes with Macet's passes, table and vertices.
//
// Both give the CPU's mesh (core/extract/macet.cpp): the same vertices in key order, the same
// triangles, positions from the same double-precision arithmetic. Per slab, compute passes
// displace the grid vertices (the push, then the one smoothing pass) into a buffer that every
// cell and edge reads; the vertex passes (HP: one invocation per vertex; GS: per triangle corner)
// find each crossing by root finding on the trilinear interpolant between the displaced end
// points. Quality Max runs the CPU's local search (core/extract/macet_search.h) between the
// smoothing and the vertex passes, on the slab's region read back from the device; relaxation
// (MacetOptions::relax) runs the CPU's pre-pass on the samples before they are uploaded.
#pragma once

#include <cstdint>
#include <string>

#include "core/extract/macet.h"
#include "core/mesh/mesh.h"
#include "core/volume/volume.h"
#include "gl_backends.h"

namespace isotile::gl {

struct MacetGlOptions {
  MacetOptions macet;  // iso, normals, quality, sweeps, relax and brick mode, as on the CPU
  // As McOptions (gl_backends.h).
  std::uint64_t memory = 0;
  std::int64_t max_brick_cells_z = 0;
  std::uint64_t capture_bytes = 0;
};

// The defines of every Macet program: MACET and core's constants as GLSL literals.
std::string macet_defines();

// Throw as macet() does for bad options, InputError when no OpenGL 4.5 context can be created,
// CapacityError as mc_histopyramid()/mc_geometry_shader() do.
Mesh macet_histopyramid(const VolumeView& view, const MacetGlOptions& options,
                        McStats* stats = nullptr);
Mesh macet_geometry_shader(const VolumeView& view, const MacetGlOptions& options,
                           McStats* stats = nullptr);

}  // namespace isotile::gl
