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
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <limits>
#include <string>

#include "core/errors.h"
#include "gl_backends.h"
#include "gl_context.h"
#include "gl_program.h"
#include "hp_pyramid.h"

namespace isotile::gl {

Mesh mc_histopyramid(const VolumeView& view, const McOptions& o, McStats* stats) {
  EdgeMethod mc;
  mc.halo = o.normals ? 1 : 0;
  return histopyramid_mesh(view, o, stats, mc);
}

Mesh histopyramid_mesh(const VolumeView& view, const McOptions& o, McStats* stats,
                       const EdgeMethod& method) {
  Scope scope;
  const DeviceInfo& dev = device();
  Mesh mesh;
  for (int a = 0; a < 3; ++a)
    if (view.dims[a] < 2) return mesh;
  const int halo = method.halo;
  const bool wide = !(view.type == ScalarType::Int8 || view.type == ScalarType::UInt8 ||
                      view.type == ScalarType::Int16 || view.type == ScalarType::UInt16 ||
                      view.type == ScalarType::Float32);
  const double sample_bytes = wide ? 8 : 4;
  const std::uint64_t budget = memory_budget(o.memory);
  // Device bytes per sample: the sample, its 16-bit code, the pyramid (8 bytes per 8 elements,
  // and 1/7 more for the upper levels).
  const Box3 box = cells_to_extract(view, o.cells);
  if (box.empty()) return mesh;
  const std::vector<Box3> slabs = plan_slabs(
      view, box, sample_bytes + 2 + 8.0 / 7.0 + method.bytes_per_sample,
      std::max(sample_bytes, method.largest_per_sample), halo, budget, o.max_brick_cells_z);
  const std::uint64_t max_binding = static_cast<std::uint64_t>(dev.max_ssbo_bytes);
  std::string normals = o.normals ? "#define NORMALS\n" : "";
  normals += method.defines;

  bind_case_tables(method.table);
  std::uint64_t vertex_base = 0;
  for (std::size_t si = 0; si < slabs.size(); ++si) {
    const Box3& cells = slabs[si];
    const Box3 region = slab_region(view, cells, halo);
    StageTimer timer;
    const Samples samples = upload_samples(view, region);
    const std::string defines = samples.defines + normals;
    std::string base_defines = defines;  // appended, not concatenated: GCC 12's -Wrestrict
    base_defines += "#define BASE\n";
    const GridUniforms grid{region, cells, view.global_dims, o.iso, view.origin, view.spacing};
    const Index3 d = {cells.extent(0) + 1, cells.extent(1) + 1, cells.extent(2) + 1};
    const std::uint64_t elements = static_cast<std::uint64_t>(d[0] * d[1] * d[2]);
    const Pyramid pyr(elements);

    const Buffer codes(((elements + 1) / 2) * 4);
    const Buffer levels(pyr.nodes * 8);
    samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
    codes.bind(GL_SHADER_STORAGE_BUFFER, 1);
    levels.bind(GL_SHADER_STORAGE_BUFFER, 2);

    timer.lap(stats ? &stats->seconds_upload : nullptr);
    // The method's own passes (Macet: its displaced grid vertices); kept until the slab is done.
    const std::vector<Buffer> kept =
        method.prepare ? method.prepare(samples, grid, defines) : std::vector<Buffer>{};
    samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);

    // (1) classify
    GLuint prog = program({{GL_COMPUTE_SHADER, "hp_classify.comp"}}, defines);
    set_grid_uniforms(prog, grid);
    glUseProgram(prog);
    dispatch((elements + 1) / 2);

    // (2) reduce, level by level
    const GLuint base = program({{GL_COMPUTE_SHADER, "hp_reduce.comp"}}, base_defines);
    const GLuint upper = program({{GL_COMPUTE_SHADER, "hp_reduce.comp"}}, defines);
    for (int l = 1; l <= pyr.levels; ++l) {
      prog = l == 1 ? base : upper;
      set_grid_uniforms(prog, grid);
      set_uniform_u(prog, "u_count", pyr.count[l]);
      set_uniform_u(prog, "u_src_count", pyr.count[l - 1]);
      set_uniform_u(prog, "u_src_offset", l >= 2 ? pyr.offset[l - 1] : 0);
      set_uniform_u(prog, "u_dst_offset", pyr.offset[l]);
      glUseProgram(prog);
      dispatch(pyr.count[l]);
    }
    // (2b) vertex offsets per node, top-down
    const Buffer offsets(pyr.nodes * 4);
    offsets.bind(GL_SHADER_STORAGE_BUFFER, 5);
    prog = program({{GL_COMPUTE_SHADER, "hp_downsweep.comp"}}, defines);
    set_grid_uniforms(prog, grid);
    pyr.set_uniforms(prog);
    glUseProgram(prog);
    for (int l = pyr.levels; l >= 1; --l) {
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_level"), l);
      dispatch(pyr.count[l]);
    }
    check("building the HistoPyramid");

    // (3) totals
    std::uint32_t totals[2] = {};
    levels.read(std::size_t{pyr.offset[pyr.levels]} * 8, 8, totals);
    const std::uint64_t n_vertices = totals[0], n_triangles = totals[1];
    // The vertices of the top plane are listed again, first, by the next slab.
    std::uint64_t shared = 0;
    const bool last = si + 1 == slabs.size();
    if (!last && n_vertices > 0) {
      prog = program({{GL_COMPUTE_SHADER, "hp_prefix.comp"}}, defines);
      set_grid_uniforms(prog, grid);
      shared = n_vertices -
               vertices_before(prog, pyr, static_cast<std::uint32_t>(d[0] * d[1] * (d[2] - 1)));
    }
    if (vertex_base + n_vertices > std::numeric_limits<std::uint32_t>::max())
      throw CapacityError(
          "the mesh would have more than 2^32 - 1 vertices, more than an "
          "in-memory mesh can index");

    timer.lap(stats ? &stats->seconds_count : nullptr);

    // (4) vertices, then triangles, in chunks that fit one storage-buffer binding.
    const std::size_t v0 = mesh.positions.size(), t0 = mesh.triangles.size();
    mesh.positions.resize(v0 + n_vertices);
    if (o.normals) mesh.normals.resize(v0 + n_vertices);
    mesh.triangles.resize(t0 + n_triangles);
    const std::uint64_t chunk_v =
        std::max<std::uint64_t>(1, std::min<std::uint64_t>(max_binding, budget / 2) / 12);
    if (n_vertices > 0) {
      prog = program({{GL_COMPUTE_SHADER, "hp_vertices.comp"}}, defines);
      set_grid_uniforms(prog, grid);
      pyr.set_uniforms(prog);
      glUseProgram(prog);
      const std::uint64_t cap = std::min(chunk_v, n_vertices);
      const Buffer pos(cap * 12), nrm(o.normals ? cap * 12 : 4);
      pos.bind(GL_SHADER_STORAGE_BUFFER, 3);
      nrm.bind(GL_SHADER_STORAGE_BUFFER, 4);
      for (std::uint64_t first = 0; first < n_vertices; first += cap) {
        const std::uint64_t n = std::min(cap, n_vertices - first);
        set_uniform_u(prog, "u_first", static_cast<std::uint32_t>(first));
        set_uniform_u(prog, "u_count", static_cast<std::uint32_t>(n));
        dispatch(n);
        pos.read(0, n * 12, mesh.positions.data() + v0 + first);
        if (o.normals) nrm.read(0, n * 12, mesh.normals.data() + v0 + first);
      }
    }
    if (n_triangles > 0) {
      prog = program({{GL_COMPUTE_SHADER, "hp_triangles.comp"}}, defines);
      set_grid_uniforms(prog, grid);
      pyr.set_uniforms(prog);
      glUseProgram(prog);
      const std::uint64_t cap = std::min(chunk_v, n_triangles);
      const Buffer tri(cap * 12);
      tri.bind(GL_SHADER_STORAGE_BUFFER, 3);
      for (std::uint64_t first = 0; first < n_triangles; first += cap) {
        const std::uint64_t n = std::min(cap, n_triangles - first);
        set_uniform_u(prog, "u_first", static_cast<std::uint32_t>(first));
        set_uniform_u(prog, "u_count", static_cast<std::uint32_t>(n));
        dispatch(n);
        tri.read(0, n * 12, mesh.triangles.data() + t0 + first);
      }
      if (vertex_base > 0) {
        const auto vb = static_cast<std::uint32_t>(vertex_base);
        tbb::parallel_for(std::size_t{t0}, mesh.triangles.size(), [&](std::size_t i) {
          for (auto& v : mesh.triangles[i]) v += vb;
        });
      }
    }
    check("writing the HistoPyramid mesh");
    timer.lap(stats ? &stats->seconds_output : nullptr);
    mesh.positions.resize(v0 + n_vertices - shared);
    if (o.normals) mesh.normals.resize(v0 + n_vertices - shared);
    vertex_base += n_vertices - shared;
  }
  glUseProgram(0);
  if (stats) stats->bricks = static_cast<int>(slabs.size());
  return mesh;
}

}  // namespace isotile::gl
