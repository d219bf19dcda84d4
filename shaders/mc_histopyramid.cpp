// Marching Cubes on the HistoPyramid path (after Dyken et al., as in the paper's Sec. IV-B), with
// the pyramid built in compute shaders over storage buffers and producing an indexed mesh.
//
// Per slab: (1) classify: one 16-bit code per element (sample of the slab's closed box: the case
// of the cell whose lower corner it is and its crossed +x/+y/+z edges); (2) reduce: a count
// pyramid of (vertices, triangles) whose nodes sum eight consecutive nodes of the level below,
// padded only to a multiple of eight per level, up to one node holding the totals; then a
// down-sweep stores each node's vertex offset; (3) read the totals back and allocate exactly;
// (4) one invocation per vertex and one per triangle descend from the top to their element.
// Summing consecutive runs makes the descent's order the element order (z, y, x), which is the
// CPU's output order, so no sort or weld is needed: a triangle corner's vertex index is its
// element's level-1 offset, plus the counts of at most seven elements before it, plus the rank of
// its axis among its element's edges. A 2x2x2-block pyramid would visit elements in block order,
// not the CPU's; measured on llvmpipe it was also no faster, and 3D textures were slower
// (docs/gl.md, "HistoPyramid layout: measured"; tests/benchmarks/bench_hp_layouts.cpp).
#include <string>

#include "gl_backends.h"
#include "gl_context.h"
#include "gl_program.h"
#include "hp_driver.h"

namespace isotile::gl {

Mesh mc_histopyramid(const VolumeView& view, const McOptions& o, McStats* stats) {
  EdgeMethod mc;
  mc.halo = o.normals ? 1 : 0;
  return histopyramid_mesh(view, o, stats, mc);
}

Mesh histopyramid_mesh(const VolumeView& view, const McOptions& o, McStats* stats,
                       const EdgeMethod& method) {
  // On the context's thread, which keeps the context current (gl_context.h).
  return on_context_thread([&]() -> Mesh {
    for (int a = 0; a < 3; ++a)
      if (view.dims[a] < 2) return {};
    HpRun run;
    run.cells = cells_to_extract(view, o.cells);
    if (run.cells.empty()) return {};
    run.iso = o.iso;
    run.memory = o.memory;
    run.max_brick_cells_z = o.max_brick_cells_z;
    run.progress = o.progress;
    HpMethod hp;
    hp.halo = method.halo;
    // Device bytes per sample besides it: its 16-bit code, the pyramid (8 bytes per 8 elements,
    // and 1/7 more for the upper levels), the method's own buffers.
    hp.bytes_per_sample = 2 + 8.0 / 7.0 + method.bytes_per_sample;
    hp.largest_per_sample = method.largest_per_sample;
    // The elements: the samples of the cells' closed box.
    hp.elements = [](const Box3& cells) {
      Box3 e = cells;
      for (int a = 0; a < 3; ++a) ++e.hi[a];
      return e;
    };
    std::string defines = o.normals ? "#define NORMALS\n" : "";
    defines += method.defines;
    hp.pyramid_defines = hp.classify_defines = hp.vertex_defines = hp.face_defines = defines;
    hp.classify_file = "hp_classify.comp";
    hp.vertex_file = "hp_vertices.comp";
    hp.face_file = "hp_triangles.comp";
    hp.faces = HpFaces::Triangles;
    hp.normals = o.normals;
    hp.bind_tables = [&] { bind_case_tables(method.table); };
    hp.prepare = method.prepare;
    return histopyramid_driver(view, run, hp, stats);
  });
}

}  // namespace isotile::gl
