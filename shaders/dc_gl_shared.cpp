// The Dual Contouring tables for the GL paths, built from the CPU's constexpr arrays.
#include "dc_gl_shared.h"

#include <array>
#include <cstdint>
#include <memory>

#include "core/extract/dual_contouring_patches.h"
#include "core/extract/dual_contouring_table.h"
#include "core/extract/isovalue_ties.h"
#include "core/extract/marching_cubes_tables.h"
#include "dc_gl.h"
#include "gl_context.h"
#include "gl_program.h"

namespace isotile::gl {

namespace {
std::unique_ptr<Buffer>& dc_tables() {
  static std::unique_ptr<Buffer> tables;
  return tables;
}
void release_dc_tables() {
  dc_tables().reset();
}
}  // namespace

void bind_dc_tables() {
  std::unique_ptr<Buffer>& tables = dc_tables();
  if (!tables) {
    at_shutdown(release_dc_tables);
    // std430 layout of DcTables in dc_common.glsl.
    struct {
      std::array<std::uint32_t, 256> patch_map{};
      std::array<std::uint32_t, 256> patch_info{};
      std::array<std::uint32_t, 48> quads{};
      std::array<std::uint32_t, 8> block_edge{};
      std::array<std::int32_t, 32> block_cell{};
    } t;
    static_assert(sizeof t == (256 + 256 + 48 + 8 + 32) * 4);
    for (int cs = 0; cs < 256; ++cs) {
      for (int e = 0; e < 12; ++e) {
        const int p = dc::kPatchTable.patch[cs][e];
        if (p >= 0) t.patch_map[cs] |= static_cast<std::uint32_t>(p) << (2 * e);
      }
      t.patch_info[cs] = dc::kPatchTable.count[cs] | (std::uint32_t{dc::kConflictFaces[cs]} << 8);
    }
    for (int code = 0; code < 16; ++code)
      for (int q = 0; q < dc::kDcTable[code].count; ++q)
        for (int v = 0; v < 4; ++v)
          t.quads[3 * code + q] |= std::uint32_t{dc::kDcTable[code].quads[q][v]} << (4 * v);
    for (int n = 0; n < 8; ++n) {
      for (int a = 0; a < 3; ++a) {
        // -1 (no such edge: never asked for) packs as 15.
        t.block_edge[n] |= (static_cast<std::uint32_t>(dc::kBlockEdge[n][a]) & 15u) << (4 * a);
        t.block_cell[4 * n + a] = dc::kBlockCell[n][a];
      }
    }
    tables = std::make_unique<Buffer>(sizeof t, &t);
  }
  tables->bind(GL_SHADER_STORAGE_BUFFER, 7);
}

std::string dc_defines(const DualContouringOptions& o, DcPass pass) {
  std::string d = "#define DC_CODES\n";
  if (pass == DcPass::Pyramid) return d;
  if (o.vertices == DcVertices::Patch) d += "#define DC_PATCH\n";
  if (pass == DcPass::Faces && o.keep_quads) d += "#define KEEP_QUADS\n";
  if (pass != DcPass::Vertices) return d;
  if (o.solver == DcSolver::Particle) d += "#define DC_PARTICLE\n";
  // Core's constants by their bits (glsl_double()), not as decimals for the driver to parse.
  if (o.solver == DcSolver::Qef) {
    d += "#define DC_QEF\n";
    d += "#define DC_JACOBI_NEGLIGIBLE " + glsl_double(dc::kJacobiNegligible) + "\n";
  }
  if (o.hermite == DcHermite::Eno) {
    d += "#define DC_ENO\n";
    d += "#define DC_ENO_KINK " + glsl_double(dc::kEnoKink) + "\n";
  }
  if (o.normals) d += "#define NORMALS\n";
  return d;
}

void set_dc_uniforms(GLuint prog, const Box3& vertex_cells, const VolumeView& view,
                     const DualContouringOptions& o) {
  auto i3 = [&](const char* name, const Index3& v) {
    glProgramUniform3i(prog, glGetUniformLocation(prog, name), static_cast<GLint>(v[0]),
                       static_cast<GLint>(v[1]), static_cast<GLint>(v[2]));
  };
  auto d1 = [&](const char* name, double v) {
    glProgramUniform1d(prog, glGetUniformLocation(prog, name), v);
  };
  i3("u_vlo", vertex_cells.lo);
  i3("u_vdims", {vertex_cells.extent(0), vertex_cells.extent(1), vertex_cells.extent(2)});
  i3("u_view_lo", view.box.lo);
  i3("u_view_hi", view.box.hi);
  d1("u_tie_offset", detail::kTieOffset);
  d1("u_rate", o.particle_rate);
  d1("u_tol2", o.particle_tolerance * o.particle_tolerance);
  glProgramUniform1i(prog, glGetUniformLocation(prog, "u_steps"), o.particle_steps);
  d1("u_qef_cutoff", o.qef_eigen_cutoff);
  glProgramUniform1i(prog, glGetUniformLocation(prog, "u_jacobi_sweeps"), dc::kJacobiSweeps);
  check("setting the Dual Contouring uniforms");
}

}  // namespace isotile::gl
