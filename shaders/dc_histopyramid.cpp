// Dual Contouring on the HistoPyramid path: the count pyramid of mc_histopyramid.cpp over a
// slab's vertex cells, counting dual vertices and quads instead of edge vertices and triangles.
//
// Per slab (face cells F, vertex cells V = F and the layer below it, within the view, as the
// CPU's brick mode): (1) dc_hp_classify.comp: one 16-bit code per cell of V (its case, the quads
// of its lower corner's edges, its patch count) and the patch of each of its crossed edges;
// (2) the pyramid (hp_reduce.comp, hp_downsweep.comp with DC_CODES); (3) the totals;
// (4) dc_hp_vertices.comp places one vertex per invocation, in key order, into a buffer kept on
// the device; (5) dc_hp_quads.comp emits one quad per invocation in the CPU's order, its corners
// found from the vertex pyramid (the corner cell's offset plus the edge's patch), split into two
// triangles by the CPU's diagonal rule from those positions. Cells in V are in (z, y, x) order and
// quads by lower sample then axis, so the output is the CPU's without a sort.
//
// The slab loop, the pyramid, the totals and the read-back are the HistoPyramid driver's
// (hp_driver.h), which Marching Cubes and Macet run on too; Dual Contouring plugs in its elements
// (the vertex cells), its passes and defines, its uniforms and tables, its patch maps, and its
// faces: quads, or two triangles each, from dc_hp_quads.comp or (geometry-shader path,
// dc_geometry_shader.cpp) from a geometry shader over the same pyramid.
#include <algorithm>
#include <string>

#include "core/errors.h"
#include "dc_gl.h"
#include "dc_gl_shared.h"
#include "gl_context.h"
#include "gl_program.h"
#include "hp_driver.h"

namespace isotile::gl {

Mesh dc_extract_gl(const VolumeView& view, const DcGlOptions& o, McStats* stats,
                   bool geometry_shader) {
  if (o.dc.particle_steps < 0)
    throw InputError("dual contouring: particle_steps must be >= 0, got " +
                     std::to_string(o.dc.particle_steps));
  if (!(o.dc.particle_rate > 0))
    throw InputError("dual contouring: particle_rate must be positive");
  // On the context's thread, which keeps the context current (gl_context.h).
  return on_context_thread([&]() -> Mesh {
    for (int a = 0; a < 3; ++a)
      if (view.dims[a] < 2) return {};
    HpMethod hp;
    hp.halo = dual_contouring_halo(o.dc);
    // The CPU's check of the view against the cells and the halo (InputError when short).
    HpRun run;
    run.cells = local_cell_box(view, o.dc.cells, hp.halo);
    if (run.cells.empty()) return {};
    for (int a = 0; a < 3; ++a) {
      run.cells.lo[a] += view.box.lo[a];
      run.cells.hi[a] += view.box.lo[a];
    }
    run.iso = o.dc.iso;
    run.memory = o.memory;
    run.max_brick_cells_z = o.max_brick_cells_z;
    run.progress = o.dc.progress;
    // Device bytes per sample besides it: its code, its patch map, the pyramid. Vertex positions
    // are not known before classification: a slab whose vertices overflow a binding is halved.
    hp.bytes_per_sample = 2 + 4 + 8.0 / 7.0;
    // The elements: the vertex cells of a slab's face cells f, f and the layer below it, within
    // the view.
    hp.elements = [box = view.box](const Box3& f) {
      Box3 v = f;
      for (int a = 0; a < 3; ++a) v.lo[a] = std::max(f.lo[a] - 1, box.lo[a]);
      return v;
    };
    hp.pyramid_defines = dc_defines(o.dc, DcPass::Pyramid);
    hp.classify_defines = dc_defines(o.dc, DcPass::Classify);
    hp.vertex_defines = dc_defines(o.dc, DcPass::Vertices);
    hp.face_defines = dc_defines(o.dc, DcPass::Faces);
    hp.classify_file = "dc_hp_classify.comp";
    hp.vertex_file = "dc_hp_vertices.comp";
    hp.face_file = "dc_hp_quads.comp";
    hp.faces = o.dc.keep_quads ? HpFaces::Quads : HpFaces::QuadsAsTriangles;
    hp.normals = o.dc.normals;
    hp.patch_maps = true;
    hp.positions_on_device = true;
    hp.bind_tables = [] {
      bind_case_tables();
      bind_dc_tables();
    };
    hp.uniforms = [&](GLuint prog, const Box3& vertex_cells) {
      set_dc_uniforms(prog, vertex_cells, view, o.dc);
    };
    if (geometry_shader) {
      const std::uint64_t capture = o.capture_bytes ? o.capture_bytes : memory_budget(o.memory) / 2;
      hp.gs_faces = [&o, capture](const std::string& defines,
                                  const std::function<void(GLuint)>& uniforms, const Pyramid& pyr,
                                  std::uint64_t elements, std::uint64_t n_faces,
                                  std::uint32_t* out) {
        return dc_gs_faces(defines, uniforms, pyr, elements, n_faces, o.dc.keep_quads, capture,
                           out);
      };
    }
    return histopyramid_driver(view, run, hp, stats);
  });
}

Mesh dc_histopyramid(const VolumeView& view, const DcGlOptions& o, McStats* stats) {
  return dc_extract_gl(view, o, stats, false);
}

}  // namespace isotile::gl
