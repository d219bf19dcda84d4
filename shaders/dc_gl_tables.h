// What the Dual Contouring GL paths share: the tables (dc_common.glsl's DcTables, from the CPU's
// constexpr arrays), the shader variant of an option set and the slab geometry's uniforms.
#pragma once

#include <glad/gl.h>

#include <string>

#include "core/extract/dual_contouring.h"
#include "core/volume/volume.h"

namespace isotile::gl {

// Binds the tables at storage-buffer binding 7 (uploaded once per context).
void bind_dc_tables();

// The defines of dc_common.glsl for `o` (solver, Hermite data, vertices, normals).
std::string dc_defines(const DualContouringOptions& o);

// The vertex cells [vlo, vlo + vdims) of a slab, the view's sample box and the solver's numbers.
void set_dc_uniforms(GLuint prog, const Box3& vertex_cells, const VolumeView& view,
                     const DualContouringOptions& o);

}  // namespace isotile::gl
