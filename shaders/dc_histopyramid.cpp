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
// Slabs: slab i + 1's vertex cells start with slab i's top layer; slab i drops those vertices,
// which slab i + 1 lists first, so a vertex's index is the running base plus its slab-local
// index in either slab.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <deque>
#include <limits>
#include <string>

#include "core/errors.h"
#include "dc_gl.h"
#include "dc_gl_shared.h"
#include "gl_context.h"
#include "gl_program.h"
#include "hp_pyramid.h"

namespace isotile::gl {

namespace {

// The vertex cells of face cells `f` (global): f and the layer below it, within the view.
Box3 vertex_cells(const VolumeView& view, const Box3& f) {
  Box3 v = f;
  for (int a = 0; a < 3; ++a) v.lo[a] = std::max(f.lo[a] - 1, view.box.lo[a]);
  return v;
}

}  // namespace

Mesh dc_extract_gl(const VolumeView& view, const DcGlOptions& o, McStats* stats,
                   bool geometry_shader) {
  if (o.dc.particle_steps < 0)
    throw InputError("dual contouring: particle_steps must be >= 0, got " +
                     std::to_string(o.dc.particle_steps));
  if (!(o.dc.particle_rate > 0))
    throw InputError("dual contouring: particle_rate must be positive");
  Scope scope;
  const DeviceInfo& dev = device();
  Mesh mesh;
  for (int a = 0; a < 3; ++a)
    if (view.dims[a] < 2) return mesh;
  const int halo = dual_contouring_halo(o.dc);
  // The CPU's check of the view against the cells and the halo (InputError when short).
  Box3 faces = local_cell_box(view, o.dc.cells, halo);
  if (faces.empty()) return mesh;
  for (int a = 0; a < 3; ++a) {
    faces.lo[a] += view.box.lo[a];
    faces.hi[a] += view.box.lo[a];
  }
  const bool wide = !(view.type == ScalarType::Int8 || view.type == ScalarType::UInt8 ||
                      view.type == ScalarType::Int16 || view.type == ScalarType::UInt16 ||
                      view.type == ScalarType::Float32);
  const double sample_bytes = wide ? 8 : 4;
  const std::uint64_t budget = memory_budget(o.memory);
  // Device bytes per sample: the sample, its code, its patch map, the pyramid. Vertex positions
  // are not known before classification: a slab whose vertices overflow a binding is halved.
  const std::vector<Box3> planned = plan_slabs(view, faces, sample_bytes + 2 + 4 + 8.0 / 7.0,
                                               sample_bytes, halo, budget, o.max_brick_cells_z);
  std::deque<Box3> slabs(planned.begin(), planned.end());
  const std::uint64_t max_binding = static_cast<std::uint64_t>(dev.max_ssbo_bytes);

  bind_case_tables();
  bind_dc_tables();
  std::uint64_t vertex_base = 0;
  int slab_count = 0, passes = 0;
  while (!slabs.empty()) {
    const Box3 cells = slabs.front();
    slabs.pop_front();
    const Box3 vcells = vertex_cells(view, cells);
    const Box3 region = slab_region(view, cells, halo);
    StageTimer timer;
    const Samples samples = upload_samples(view, region);
    const std::string pyramid = samples.defines + dc_defines(o.dc, DcPass::Pyramid);
    const std::string classify = samples.defines + dc_defines(o.dc, DcPass::Classify);
    const std::string vertices = samples.defines + dc_defines(o.dc, DcPass::Vertices);
    const std::string faces = samples.defines + dc_defines(o.dc, DcPass::Faces);
    std::string base_defines = pyramid;
    base_defines += "#define BASE\n";
    const GridUniforms grid{region, cells, view.global_dims, o.dc.iso, view.origin, view.spacing};
    const std::uint64_t elements =
        static_cast<std::uint64_t>(vcells.extent(0) * vcells.extent(1) * vcells.extent(2));
    const Pyramid pyr(elements);
    auto uniforms = [&](GLuint prog) {
      set_grid_uniforms(prog, grid);
      set_dc_uniforms(prog, vcells, view, o.dc);
    };

    const Buffer codes(((elements + 1) / 2) * 4);
    const Buffer maps(elements * 4);
    const Buffer levels(pyr.nodes * 8);
    samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
    codes.bind(GL_SHADER_STORAGE_BUFFER, 1);
    levels.bind(GL_SHADER_STORAGE_BUFFER, 2);
    maps.bind(GL_SHADER_STORAGE_BUFFER, 6);
    timer.lap(stats ? &stats->seconds_upload : nullptr);

    // (1) classify
    GLuint prog = program({{GL_COMPUTE_SHADER, "dc_hp_classify.comp"}}, classify);
    uniforms(prog);
    glUseProgram(prog);
    dispatch((elements + 1) / 2);

    // (2) the pyramid, then vertex offsets per node
    const GLuint base = program({{GL_COMPUTE_SHADER, "hp_reduce.comp"}}, base_defines);
    const GLuint upper = program({{GL_COMPUTE_SHADER, "hp_reduce.comp"}}, pyramid);
    for (int l = 1; l <= pyr.levels; ++l) {
      prog = l == 1 ? base : upper;
      set_uniform_u(prog, "u_count", pyr.count[l]);
      set_uniform_u(prog, "u_src_count", pyr.count[l - 1]);
      set_uniform_u(prog, "u_src_offset", l >= 2 ? pyr.offset[l - 1] : 0);
      set_uniform_u(prog, "u_dst_offset", pyr.offset[l]);
      glUseProgram(prog);
      dispatch(pyr.count[l]);
    }
    const Buffer offsets(pyr.nodes * 4);
    offsets.bind(GL_SHADER_STORAGE_BUFFER, 5);
    prog = program({{GL_COMPUTE_SHADER, "hp_downsweep.comp"}}, pyramid);
    pyr.set_uniforms(prog);
    glUseProgram(prog);
    for (int l = pyr.levels; l >= 1; --l) {
      glProgramUniform1i(prog, glGetUniformLocation(prog, "u_level"), l);
      dispatch(pyr.count[l]);
    }
    check("building the Dual Contouring HistoPyramid");

    // (3) totals
    std::uint32_t totals[2] = {};
    levels.read(std::size_t{pyr.offset[pyr.levels]} * 8, 8, totals);
    const std::uint64_t n_vertices = totals[0], n_quads = totals[1];
    if (n_vertices * 12 > max_binding && cells.extent(2) > 1) {
      // Too many vertices for one buffer: the slab in two halves.
      Box3 lower = cells, upper_half = cells;
      lower.hi[2] = upper_half.lo[2] = cells.lo[2] + cells.extent(2) / 2;
      slabs.push_front(upper_half);
      slabs.push_front(lower);
      continue;
    }
    if (n_vertices * 12 > max_binding)
      throw CapacityError("one cell layer of " + std::to_string(cells.extent(0)) + " x " +
                          std::to_string(cells.extent(1)) +
                          " cells has more dual vertices than the GL device's largest buffer "
                          "holds; use the CPU backend");
    // The vertices of the top layer are listed again, first, by the next slab.
    std::uint64_t shared = 0;
    const bool last = slabs.empty();
    if (!last && n_vertices > 0) {
      prog = program({{GL_COMPUTE_SHADER, "hp_prefix.comp"}}, pyramid);
      shared = n_vertices -
               vertices_before(prog, pyr,
                               static_cast<std::uint32_t>(vcells.extent(0) * vcells.extent(1) *
                                                          (vcells.extent(2) - 1)));
    }
    if (vertex_base + n_vertices > std::numeric_limits<std::uint32_t>::max())
      throw CapacityError(
          "the mesh would have more than 2^32 - 1 vertices, more than an in-memory mesh can "
          "index");
    timer.lap(stats ? &stats->seconds_count : nullptr);

    // (4) vertices
    const std::size_t v0 = mesh.positions.size();
    mesh.positions.resize(v0 + n_vertices);
    if (o.dc.normals) mesh.normals.resize(v0 + n_vertices);
    const Buffer pos(n_vertices * 12), nrm(o.dc.normals ? n_vertices * 12 : 4);
    if (n_vertices > 0) {
      prog = program({{GL_COMPUTE_SHADER, "dc_hp_vertices.comp"}}, vertices);
      uniforms(prog);
      pyr.set_uniforms(prog);
      set_uniform_u(prog, "u_count", static_cast<std::uint32_t>(n_vertices));
      glUseProgram(prog);
      pos.bind(GL_SHADER_STORAGE_BUFFER, 3);
      nrm.bind(GL_SHADER_STORAGE_BUFFER, 4);
      dispatch(n_vertices);
      pos.read(0, n_vertices * 12, mesh.positions.data() + v0);
      if (o.dc.normals) nrm.read(0, n_vertices * 12, mesh.normals.data() + v0);
    }

    // (5) quads (or their triangles), in chunks that fit one storage-buffer binding
    const std::size_t per_quad = o.dc.keep_quads ? 16 : 24;
    const std::size_t f0 = o.dc.keep_quads ? mesh.quads.size() : mesh.triangles.size();
    if (o.dc.keep_quads)
      mesh.quads.resize(f0 + n_quads);
    else
      mesh.triangles.resize(f0 + 2 * n_quads);
    if (n_quads > 0 && geometry_shader) {
      pos.bind(GL_SHADER_STORAGE_BUFFER, 4);
      std::uint32_t* out = o.dc.keep_quads ? mesh.quads[f0].data() : mesh.triangles[f0].data();
      passes += dc_gs_faces(faces, uniforms, pyr, elements, n_quads, o.dc.keep_quads,
                            o.capture_bytes ? o.capture_bytes : budget / 2, out);
    } else if (n_quads > 0) {
      prog = program({{GL_COMPUTE_SHADER, "dc_hp_quads.comp"}}, faces);
      uniforms(prog);
      pyr.set_uniforms(prog);
      glUseProgram(prog);
      pos.bind(GL_SHADER_STORAGE_BUFFER, 4);
      const std::uint64_t cap = std::min<std::uint64_t>(
          n_quads,
          std::max<std::uint64_t>(1, std::min<std::uint64_t>(max_binding, budget / 2) / per_quad));
      const Buffer out(cap * per_quad);
      out.bind(GL_SHADER_STORAGE_BUFFER, 3);
      for (std::uint64_t first = 0; first < n_quads; first += cap) {
        const std::uint64_t n = std::min(cap, n_quads - first);
        set_uniform_u(prog, "u_first", static_cast<std::uint32_t>(first));
        set_uniform_u(prog, "u_count", static_cast<std::uint32_t>(n));
        dispatch(n);
        if (o.dc.keep_quads)
          out.read(0, n * per_quad, mesh.quads.data() + f0 + first);
        else
          out.read(0, n * per_quad, mesh.triangles.data() + f0 + 2 * first);
      }
    }
    if (n_quads > 0) {
      if (vertex_base > 0) {
        const auto vb = static_cast<std::uint32_t>(vertex_base);
        if (o.dc.keep_quads)
          tbb::parallel_for(f0, mesh.quads.size(), [&](std::size_t i) {
            for (auto& v : mesh.quads[i]) v += vb;
          });
        else
          tbb::parallel_for(f0, mesh.triangles.size(), [&](std::size_t i) {
            for (auto& v : mesh.triangles[i]) v += vb;
          });
      }
    }
    check("writing the Dual Contouring mesh");
    timer.lap(stats ? &stats->seconds_output : nullptr);
    mesh.positions.resize(v0 + n_vertices - shared);
    if (o.dc.normals) mesh.normals.resize(v0 + n_vertices - shared);
    vertex_base += n_vertices - shared;
    ++slab_count;
  }
  glUseProgram(0);
  if (stats) {
    stats->bricks = slab_count;
    stats->capture_passes = passes;
  }
  return mesh;
}

Mesh dc_histopyramid(const VolumeView& view, const DcGlOptions& o, McStats* stats) {
  return dc_extract_gl(view, o, stats, false);
}

}  // namespace isotile::gl
