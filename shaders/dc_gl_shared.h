// What the Dual Contouring GL paths share: the tables (dc_common.glsl's DcTables, from the CPU's
// constexpr arrays), the shader variant of an option set and the slab geometry's uniforms.
#pragma once

#include <glad/gl.h>

#include <cstdint>
#include <functional>
#include <string>

#include "core/extract/dual_contouring.h"
#include "core/volume/volume.h"
#include "dc_gl.h"
#include "hp_pyramid.h"

namespace isotile::gl {

// Binds the tables at storage-buffer binding 7 (uploaded once per context).
void bind_dc_tables();

// The defines of dc_common.glsl each pass needs, no more (every variant is a program compiled
// at run time): the pyramid's, the classification's (vertices), the vertex pass's (vertices,
// solver, Hermite data, normals) and the face passes' (vertices, quads).
enum class DcPass { Pyramid, Classify, Vertices, Faces };
std::string dc_defines(const DualContouringOptions& o, DcPass pass);

// The vertex cells [vlo, vlo + vdims) of a slab, the view's sample box and the solver's numbers.
void set_dc_uniforms(GLuint prog, const Box3& vertex_cells, const VolumeView& view,
                     const DualContouringOptions& o);

// Dual Contouring on the HistoPyramid driver (hp_driver.h, dc_histopyramid.cpp): classification,
// the count pyramid and the vertex pass, then the faces from the pyramid's quad pass or, with
// `geometry_shader`, from dc_gs_faces.
Mesh dc_extract_gl(const VolumeView& view, const DcGlOptions& o, McStats* stats,
                   bool geometry_shader);

// The geometry-shader emission of one slab (dc_geometry_shader.cpp), with the slab's codes,
// pyramid, offsets, patch maps and vertex positions bound as the pipeline binds them: the
// `n_quads` quads of its `elements` elements, as 4 (keep_quads) or 6 (two triangles) slab-local
// vertex indices each, into `out`, through a capture buffer of at most `capture_bytes`. `uniforms`
// sets a program's slab uniforms. Returns the number of draws.
int dc_gs_faces(const std::string& defines, const std::function<void(GLuint)>& uniforms,
                const Pyramid& pyr, std::uint64_t elements, std::uint64_t n_quads, bool keep_quads,
                std::uint64_t capture_bytes, std::uint32_t* out);

}  // namespace isotile::gl
