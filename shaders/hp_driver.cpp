#include "hp_driver.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <utility>

#include "core/errors.h"
#include "gl_context.h"
#include "sample_upload.h"
#include "stage_clock.h"

namespace isotile::gl {

namespace {

// Indices per face as read back, and the mesh's face array they land in.
std::uint64_t face_words(HpFaces f) {
  return f == HpFaces::Triangles ? 3 : f == HpFaces::Quads ? 4 : 6;
}

// Adds `base` to every vertex index of `faces` from element `first` on.
template <class Faces>
void offset_indices(Faces& faces, std::size_t first, std::uint32_t base) {
  if (base == 0) return;
  tbb::parallel_for(first, faces.size(), [&](std::size_t i) {
    for (auto& v : faces[i]) v += base;
  });
}

// One chunk of an output pass: the current program `prog` over items [first, first + k), each
// chunk's outputs at the start of the pass's buffers.
struct Chunk {
  std::uint64_t first = 0, k = 0;
  StageClock::Mark start{}, done{};  // around the dispatch, on the device
};

// `elements`: the invocations of a per-element pass (HpOutput::Scatter; each writes its outputs
// that fall in the chunk), else 0: one invocation per output of the chunk.
Chunk dispatch_chunk(GLuint prog, std::uint64_t first, std::uint64_t k, std::uint64_t elements,
                     StageClock* clock, int& chunks) {
  ++chunks;
  set_uniform_u(prog, "u_first", static_cast<std::uint32_t>(first));
  set_uniform_u(prog, "u_count", static_cast<std::uint32_t>(k));
  Chunk c{first, k, device_mark(clock), {}};
  dispatch(elements > 0 ? elements : k);
  c.done = device_mark(clock);
  return c;
}

// Reads chunk `c` back from `out` (bytes_per_item each) to `dst`, and `out2` to `dst2` when given.
// With a clock, the pass counts as `stage` and the copies as the read-back.
void read_chunk(const Chunk& c, std::uint64_t bytes_per_item, const Buffer& out, void* dst,
                StageClock* clock, GlStage stage, const Buffer* out2 = nullptr,
                void* dst2 = nullptr) {
  const StageClock::Mark before = cpu_mark(clock);
  const std::uint64_t at = c.first * bytes_per_item, bytes = c.k * bytes_per_item;
  out.read(0, bytes, static_cast<char*>(dst) + at);
  if (out2) out2->read(0, bytes, static_cast<char*>(dst2) + at);
  if (clock) {
    clock->add(stage, c.start, c.done);
    clock->add_wait(GlStage::Readback, c.done, before, StageClock::cpu_mark());
  }
}

// Runs the current program `prog` over `n` items in chunks of at most `cap`, each read back
// before the next is dispatched (read_chunk()).
void dispatch_chunks(GLuint prog, std::uint64_t n, std::uint64_t cap, std::uint64_t elements,
                     std::uint64_t bytes_per_item, const Buffer& out, void* dst, StageClock* clock,
                     int& chunks, GlStage stage, const Buffer* out2 = nullptr,
                     void* dst2 = nullptr) {
  for (std::uint64_t first = 0; first < n; first += cap)
    read_chunk(dispatch_chunk(prog, first, std::min(cap, n - first), elements, clock, chunks),
               bytes_per_item, out, dst, clock, stage, out2, dst2);
}

}  // namespace

Mesh histopyramid_driver(const VolumeView& view, const HpRun& run, const HpMethod& method,
                         McStats* stats) {
  Scope scope;
  const DeviceInfo& dev = device();
  Mesh mesh;
  // The samples are on the device as stored (sample_upload.h).
  const double sample_bytes = static_cast<double>(scalar_size(view.type));
  const std::uint64_t budget = memory_budget(run.memory);
  const HpOutput output = default_hp_output();
  const bool scatter = output == HpOutput::Scatter;
  // The per-element output passes keep the faces' offsets too: 4 bytes per pyramid node, at most
  // one node per 7 elements (the levels above the first add a seventh of it).
  const double face_offset_bytes = scatter ? 4.0 / 7.0 + 0.01 : 0.0;
  // The next slab's samples are uploaded while this slab's pyramid is built (below).
  const std::vector<Box3> planned = plan_overlapped_slabs(
      view, run.cells, sample_bytes, method.bytes_per_sample + face_offset_bytes,
      method.largest_per_sample, method.halo, budget, run.max_brick_cells_z);
  std::deque<Box3> slabs(planned.begin(), planned.end());
  const std::uint64_t max_binding = static_cast<std::uint64_t>(dev.max_ssbo_bytes);
  const std::uint64_t words = face_words(method.faces);
  // Output buffers: at most one binding, and half the budget.
  const std::uint64_t out_bytes = std::max<std::uint64_t>(1, std::min(max_binding, budget / 2));

  method.bind_tables();
  // Timer queries only when the stages are asked for.
  StageClock clock_storage;
  StageClock* const clock = stats ? &clock_storage : nullptr;
  std::uint64_t vertex_base = 0;
  int slab_count = 0, draws = 0, early = 0, chunks = 0, pyramid_passes = 0;
  progress_begin(run.progress, isotile::Stage::Extract, static_cast<std::int64_t>(planned.size()));
  // The next slab's region and samples, uploaded early (unused when that slab is split).
  std::optional<std::pair<Box3, Samples>> next;
  auto same_box = [](const Box3& a, const Box3& b) { return a.lo == b.lo && a.hi == b.hi; };
  while (!slabs.empty()) {
    const Box3 cells = slabs.front();
    slabs.pop_front();
    const Box3 elems = method.elements(cells);
    const Box3 region = slab_region(view, cells, method.halo);
    const bool uploaded = next && same_box(next->first, region);
    early += uploaded;
    const Samples samples =
        uploaded ? std::move(next->second) : upload_samples(view, region, clock);
    next.reset();
    const std::string pyramid = samples.defines + method.pyramid_defines;
    const GridUniforms grid{region, cells, view.global_dims, run.iso, view.origin, view.spacing};
    auto uniforms = [&](GLuint prog) {
      set_grid_uniforms(prog, grid);
      if (method.uniforms) method.uniforms(prog, elems);
    };
    const std::uint64_t elements =
        static_cast<std::uint64_t>(elems.extent(0) * elems.extent(1) * elems.extent(2));
    const Pyramid pyr(elements);

    const Buffer codes(((elements + 1) / 2) * 4);
    const Buffer levels(pyr.nodes * 8);
    const Buffer maps(method.patch_maps ? elements * 4 : 4);
    samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
    codes.bind(GL_SHADER_STORAGE_BUFFER, 1);
    levels.bind(GL_SHADER_STORAGE_BUFFER, 2);
    if (method.patch_maps) maps.bind(GL_SHADER_STORAGE_BUFFER, 6);
    // The method's own passes (Macet: its displaced grid vertices); kept until the slab is done.
    const StageClock::Mark prepare_start = device_mark(clock);
    const std::vector<Buffer> kept =
        method.prepare ? method.prepare(samples, grid, samples.defines + method.classify_defines)
                       : std::vector<Buffer>{};
    samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
    const StageClock::Mark classify_start = device_mark(clock);
    if (clock && method.prepare) clock->add(GlStage::Prepare, prepare_start, classify_start);

    // (1) classify
    GLuint prog = program({{GL_COMPUTE_SHADER, method.classify_file}},
                          samples.defines + method.classify_defines);
    uniforms(prog);
    glUseProgram(prog);
    dispatch((elements + 1) / 2);
    const StageClock::Mark scan_start = device_mark(clock);
    if (clock) clock->add(GlStage::Classify, classify_start, scan_start);

    // (2) the count pyramid, several levels per pass (hp_pyramid.h), then each node's vertex
    // offset, top-down
    pyramid_passes += reduce_levels(pyr, pyramid);
    // The per-element output passes start each element's faces from the faces' offsets too.
    const Buffer offsets(pyr.nodes * 4 * (scatter ? 2 : 1));
    offsets.bind(GL_SHADER_STORAGE_BUFFER, 5);
    pyramid_passes += sweep_offsets(pyr, pyramid, offsets, 0, scatter);
    check("building the HistoPyramid");

    // (3) totals
    const StageClock::Mark scan_done = device_mark(clock);
    // The next slab's upload: its rows are copied into the staging buffers while the device
    // builds this slab's pyramid, before the totals' read-back waits for it.
    if (!slabs.empty()) {
      submit();  // the pyramid's passes start before the CPU copies rows
      const Box3 next_region = slab_region(view, slabs.front(), method.halo);
      next.emplace(next_region, upload_samples(view, next_region, clock));
    }
    const StageClock::Mark totals_read = cpu_mark(clock);
    std::uint32_t totals[2] = {};
    levels.read(std::size_t{pyr.offset[pyr.levels]} * 8, 8, totals);
    if (clock) {
      clock->add(GlStage::Scan, scan_start, scan_done);
      clock->add_wait(GlStage::Readback, scan_done, totals_read, StageClock::cpu_mark());
    }
    const std::uint64_t n_vertices = totals[0], n_faces = totals[1];
    if (method.positions_on_device && n_vertices * 12 > max_binding) {
      if (cells.extent(2) > 1) {
        // Too many vertices for one buffer: the slab in two halves.
        Box3 lower = cells, upper_half = cells;
        lower.hi[2] = upper_half.lo[2] = cells.lo[2] + cells.extent(2) / 2;
        slabs.push_front(upper_half);
        slabs.push_front(lower);
        continue;
      }
      throw CapacityError("one cell layer of " + std::to_string(cells.extent(0)) + " x " +
                          std::to_string(cells.extent(1)) +
                          " cells has more vertices than the GL device's largest buffer holds; "
                          "use the CPU backend");
    }
    // The vertices of the top layer of elements are listed again, first, by the next slab.
    std::uint64_t shared = 0;
    if (!slabs.empty() && n_vertices > 0) {
      const StageClock::Mark prefix_start = device_mark(clock);
      prog = program({{GL_COMPUTE_SHADER, "hp_prefix.comp"}}, pyramid);
      uniforms(prog);
      shared = n_vertices -
               vertices_before(prog, pyr,
                               static_cast<std::uint32_t>(elems.extent(0) * elems.extent(1) *
                                                          (elems.extent(2) - 1)));
      if (clock) clock->add(GlStage::Scan, prefix_start, StageClock::cpu_mark());
    }
    if (vertex_base + n_vertices > std::numeric_limits<std::uint32_t>::max())
      throw CapacityError(
          "the mesh would have more than 2^32 - 1 vertices, more than an in-memory mesh can "
          "index");

    // (4) vertices, in chunks unless the face pass reads them all; (5) faces, in chunks that fit
    // one binding, or from the geometry shader
    const std::uint64_t vcap =
        method.positions_on_device
            ? std::max<std::uint64_t>(n_vertices, 1)
            : std::max<std::uint64_t>(1, std::min(out_bytes / 12, n_vertices));
    const Buffer pos(vcap * 12), nrm(method.normals ? vcap * 12 : 4);
    GLuint vertex_prog = 0;
    if (n_vertices > 0) {
      vertex_prog = program({{GL_COMPUTE_SHADER, method.vertex_file}},
                            output_pass_defines(samples.defines + method.vertex_defines, output));
      uniforms(vertex_prog);
      pyr.set_uniforms(vertex_prog);
    }
    const std::string faces = samples.defines + method.face_defines;
    const bool face_pass = n_faces > 0 && !method.gs_faces;
    GLuint face_prog = 0;
    std::uint64_t fcap = 1;
    if (face_pass) {
      face_prog =
          program({{GL_COMPUTE_SHADER, method.face_file}}, output_pass_defines(faces, output));
      uniforms(face_prog);
      pyr.set_uniforms(face_prog);
      fcap = std::max<std::uint64_t>(1, std::min(out_bytes / (words * 4), n_faces));
    }
    const Buffer face_buffer(face_pass ? fcap * words * 4 : 4);
    auto use_vertex_pass = [&] {
      glUseProgram(vertex_prog);
      pos.bind(GL_SHADER_STORAGE_BUFFER, 3);
      nrm.bind(GL_SHADER_STORAGE_BUFFER, 4);
    };
    auto use_face_pass = [&] {
      glUseProgram(face_prog);
      face_buffer.bind(GL_SHADER_STORAGE_BUFFER, 3);
      if (method.positions_on_device) pos.bind(GL_SHADER_STORAGE_BUFFER, 4);
    };
    // Where each pass fits one chunk (most slabs), both are dispatched and submitted before the
    // CPU sizes the mesh's arrays, so that the device runs them while the CPU zeroes the arrays and
    // takes their pages' first-touch faults (gyroid 256^3's 23 MB of positions and triangles: 11 ms
    // in a fresh process on a 2-core VM); the reads follow.
    const bool ahead = n_vertices <= vcap && n_faces <= fcap && !method.gs_faces;
    const std::uint64_t per_element = scatter ? elements : 0;
    Chunk vertex_chunk, face_chunk;
    if (ahead && n_vertices > 0) {
      use_vertex_pass();
      vertex_chunk = dispatch_chunk(vertex_prog, 0, n_vertices, per_element, clock, chunks);
    }
    if (ahead && face_pass) {
      use_face_pass();
      face_chunk = dispatch_chunk(face_prog, 0, n_faces, per_element, clock, chunks);
    }
    if (ahead) submit();
    const bool quads = method.faces == HpFaces::Quads;
    const std::size_t v0 = mesh.positions.size();
    const std::size_t f0 = quads ? mesh.quads.size() : mesh.triangles.size();
    tbb::parallel_invoke(
        [&] {
          mesh.positions.resize(v0 + n_vertices);
          if (method.normals) mesh.normals.resize(v0 + n_vertices);
        },
        [&] {
          if (quads)
            mesh.quads.resize(f0 + n_faces);
          else
            mesh.triangles.resize(f0 + n_faces * words / 3);
        });
    std::uint32_t* out = n_faces == 0 ? nullptr
                         : quads      ? mesh.quads[f0].data()
                                      : mesh.triangles[f0].data();
    if (ahead) {
      if (n_vertices > 0)
        read_chunk(vertex_chunk, 12, pos, mesh.positions.data() + v0, clock, GlStage::Vertices,
                   method.normals ? &nrm : nullptr,
                   method.normals ? mesh.normals.data() + v0 : nullptr);
      if (face_pass) read_chunk(face_chunk, words * 4, face_buffer, out, clock, GlStage::Faces);
    } else {
      if (n_vertices > 0) {
        use_vertex_pass();
        dispatch_chunks(vertex_prog, n_vertices, vcap, per_element, 12, pos,
                        mesh.positions.data() + v0, clock, chunks, GlStage::Vertices,
                        method.normals ? &nrm : nullptr,
                        method.normals ? mesh.normals.data() + v0 : nullptr);
      }
      if (n_faces > 0 && method.gs_faces) {
        if (method.positions_on_device) pos.bind(GL_SHADER_STORAGE_BUFFER, 4);
        const StageClock::Mark faces_start = device_mark(clock);
        draws += method.gs_faces(faces, uniforms, pyr, elements, n_faces, out);
        if (clock) clock->add(GlStage::Faces, faces_start, StageClock::cpu_mark());
      } else if (face_pass) {
        use_face_pass();
        dispatch_chunks(face_prog, n_faces, fcap, per_element, words * 4, face_buffer, out, clock,
                        chunks, GlStage::Faces);
      }
    }
    if (quads)
      offset_indices(mesh.quads, f0, static_cast<std::uint32_t>(vertex_base));
    else
      offset_indices(mesh.triangles, f0, static_cast<std::uint32_t>(vertex_base));
    check("writing the HistoPyramid mesh");
    mesh.positions.resize(v0 + n_vertices - shared);
    if (method.normals) mesh.normals.resize(v0 + n_vertices - shared);
    vertex_base += n_vertices - shared;
    ++slab_count;
    progress_advance(run.progress);  // a halved slab advances twice: the fraction stops at 1
  }
  glUseProgram(0);
  if (stats) {
    stats->bricks = slab_count;
    stats->capture_passes = draws;
    stats->early_uploads = early;
    stats->output_chunks = chunks;
    stats->pyramid_passes = pyramid_passes;
    stats->times = clock->collect();
  }
  return mesh;
}

}  // namespace isotile::gl
