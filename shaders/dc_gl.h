// The OpenGL Dual Contouring extractors (HistoPyramid and geometry-shader paths).
//
// Both give the CPU's mesh (core/extract/dual_contouring.h): the same vertices in key order (cell
// by cell, then patch), the same quads or triangles in the CPU's order, positions computed with
// the CPU's double-precision arithmetic (decisions on values in double with `precise`, tables
// uploaded from the CPU's constexpr arrays). Slabs along z as for Marching Cubes (gl_backends.h),
// and the brick contract's `cells` box.
#pragma once

#include <cstdint>

#include "core/extract/dual_contouring.h"
#include "core/mesh/mesh.h"
#include "core/volume/volume.h"
#include "gl_backends.h"

namespace isotile::gl {

struct DcGlOptions {
  DualContouringOptions dc;  // as on the CPU, `cells` included
  // As McOptions: device memory to plan slabs for (0: from the driver), for tests a cap on a
  // slab's cells along z and (geometry-shader path) the capture buffer's bytes.
  std::uint64_t memory = 0;
  std::int64_t max_brick_cells_z = 0;
  std::uint64_t capture_bytes = 0;
};

// Every option of DualContouringOptions runs on GL. Throw InputError for invalid options (as the
// CPU) or when no context can be made, CapacityError when the mesh needs more than 2^32 - 1
// vertices or one x-y slab does not fit the device.
Mesh dc_histopyramid(const VolumeView& view, const DcGlOptions& options, McStats* stats = nullptr);
Mesh dc_geometry_shader(const VolumeView& view, const DcGlOptions& options,
                        McStats* stats = nullptr);

}  // namespace isotile::gl
