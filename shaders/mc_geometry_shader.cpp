// Marching Cubes on the geometry-shader path (the paper's Sec. IV-A): one point per cell, the
// geometry shader classifies it with the CPU's case tables and emits its triangles, captured by
// transform feedback; the triangle soup is then welded into an indexed mesh by global edge key.
//
// Capture limits: a binding of more than 2 GiB loses data silently on Mesa (see gl.md), so the
// capture range is at most 2 GiB (and what memory allows). The GL_PRIMITIVES_GENERATED and
// GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN queries detect an overflow (written < generated); the
// triangles of the last, possibly partial, cell are dropped and the draw resumes at that cell
// into a buffer sized from the generated count. Transform feedback keeps primitive order, so the
// soup is cell by cell in table order, and welding in key order gives the CPU's mesh.
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <limits>
#include <numeric>
#include <optional>
#include <string>
#include <utility>

#include "core/errors.h"
#include "gl_backends.h"
#include "gl_context.h"
#include "gl_program.h"
#include "sample_upload.h"
#include "stage_clock.h"

namespace isotile::gl {

namespace {

// The largest capture range (bytes) a binding may have: 2 GiB.
constexpr std::uint64_t kMaxCaptureBytes = std::uint64_t{1} << 31;

struct Soup {
  std::vector<std::uint64_t> keys;  // per triangle corner: lin(s) * 3 + axis, global
  std::vector<Vec3f> positions, normals;
  std::vector<char> in_box;  // per triangle: its cell is one of the cells asked for
};

// An initial capture size in triangles: enough for a smooth surface crossing the slab, so that
// most slabs need one pass; a second pass is sized from the generated count.
std::uint64_t first_guess(const Box3& cells) {
  const std::uint64_t x = cells.extent(0), y = cells.extent(1), z = cells.extent(2);
  return 8 * (x * y + y * z + x * z) + 64;
}

}  // namespace

Mesh mc_geometry_shader(const VolumeView& view, const McOptions& o, McStats* stats) {
  EdgeMethod mc;
  mc.halo = o.normals ? 1 : 0;
  return geometry_shader_mesh(view, o, stats, mc);
}

Mesh geometry_shader_mesh(const VolumeView& view, const McOptions& o, McStats* stats,
                          const EdgeMethod& method) {
  // On the context's thread, which keeps the context current (gl_context.h).
  return on_context_thread([&]() -> Mesh {
    Mesh mesh;
    for (int a = 0; a < 3; ++a)
      if (view.dims[a] < 2) return mesh;
    const int halo = method.halo;
    // The samples are on the device as stored (sample_upload.h).
    const double sample_bytes = static_cast<double>(scalar_size(view.type));
    const std::uint64_t budget = memory_budget(o.memory);
    // Half the budget for the samples, half for the capture.
    const Box3 box = cells_to_extract(view, o.cells);
    if (box.empty()) return mesh;
    // The next slab's samples are uploaded while this slab's first draw runs (below).
    const std::vector<Box3> slabs =
        plan_overlapped_slabs(view, box, sample_bytes, method.bytes_per_sample,
                              method.largest_per_sample, halo, budget / 2, o.max_brick_cells_z);
    // In brick mode the vertices on the box's upper faces are listed although no cell of the box
    // uses some of them: a slab there draws one more layer of cells, whose corners are welded too
    // and whose triangles are dropped.
    auto drawn_cells = [&](const Box3& slab) {
      Box3 cells = slab;
      for (int a = 0; a < 3; ++a)
        if (slab.hi[a] == box.hi[a]) cells.hi[a] = std::min(box.hi[a] + 1, view.global_dims[a] - 1);
      return cells;
    };

    // Captured per corner: key, cell, position (and normal): 32-bit words.
    const std::size_t words = o.normals ? 8 : 5;
    const std::size_t tri_bytes = 3 * words * 4;
    std::uint64_t limit =
        o.capture_bytes ? o.capture_bytes : std::min(kMaxCaptureBytes, budget / 2);
    limit = std::min(limit, kMaxCaptureBytes) / tri_bytes;
    limit = std::max<std::uint64_t>(limit, 5);  // one cell's triangles always fit

    std::vector<const char*> varyings = {"tf_key", "tf_cell", "tf_pos"};
    if (o.normals) varyings.push_back("tf_nrm");
    const GLuint vao = empty_vertex_array();
    GLuint queries[2];
    glCreateQueries(GL_PRIMITIVES_GENERATED, 1, &queries[0]);
    glCreateQueries(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, 1, &queries[1]);
    bind_case_tables(method.table);
    glEnable(GL_RASTERIZER_DISCARD);
    glBindVertexArray(vao);

    progress_begin(o.progress, isotile::Stage::Extract, static_cast<std::int64_t>(slabs.size()));
    Soup soup;
    int passes = 0;
    // Timer queries only when the stages are asked for.
    StageClock clock_storage;
    StageClock* const clock = stats ? &clock_storage : nullptr;
    std::vector<std::uint32_t> staging;
    // The next slab's samples, uploaded while this slab's first draw runs.
    std::optional<Samples> next;
    int early = 0;
    try {
      for (std::size_t s = 0; s < slabs.size(); ++s) {
        const Box3 cells = drawn_cells(slabs[s]);
        const Box3 region = slab_region(view, cells, halo);
        early += next.has_value();
        const Samples samples = next ? std::move(*next) : upload_samples(view, region, clock);
        next.reset();
        std::string defines = samples.defines + (o.normals ? "#define NORMALS\n" : "");
        defines += method.defines;
        const GridUniforms grid{region, cells, view.global_dims, o.iso, view.origin, view.spacing};
        samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
        // The method's own compute passes (Macet: its displaced grid vertices), kept until the slab
        // is done.
        const StageClock::Mark prepare_start = device_mark(clock);
        const std::vector<Buffer> kept =
            method.prepare ? method.prepare(samples, grid, defines) : std::vector<Buffer>{};
        if (clock && method.prepare)
          clock->add(GlStage::Prepare, prepare_start, clock->device_mark());
        const GLuint prog =
            program({{GL_VERTEX_SHADER, "gs_mc.vert"}, {GL_GEOMETRY_SHADER, "gs_mc.geom"}}, defines,
                    varyings);
        set_grid_uniforms(prog, grid);
        glUseProgram(prog);
        samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
        const Index3 d = {cells.extent(0) + 1, cells.extent(1) + 1, cells.extent(2) + 1};
        const std::int64_t n_cells = cells.extent(0) * cells.extent(1) * cells.extent(2);
        std::uint64_t cap = std::min(limit, first_guess(cells));
        Buffer capture(cap * tri_bytes);
        for (std::int64_t first = 0; first < n_cells;) {
          const StageClock::Mark draw_start = device_mark(clock);
          glBindBufferRange(GL_TRANSFORM_FEEDBACK_BUFFER, 0, capture.id(), 0,
                            static_cast<GLsizeiptr>(cap * tri_bytes));
          glBeginQuery(GL_PRIMITIVES_GENERATED, queries[0]);
          glBeginQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, queries[1]);
          glBeginTransformFeedback(GL_TRIANGLES);
          glDrawArrays(GL_POINTS, static_cast<GLint>(first), static_cast<GLsizei>(n_cells - first));
          glEndTransformFeedback();
          glEndQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN);
          glEndQuery(GL_PRIMITIVES_GENERATED);
          // The next slab's rows are copied into the staging buffers while the device draws, before
          // the queries' results wait for it.
          if (!next && s + 1 < slabs.size()) {
            submit();  // the draw starts before the CPU copies rows
            next = upload_samples(view, slab_region(view, drawn_cells(slabs[s + 1]), halo), clock);
          }
          GLuint64 generated = 0, written = 0;
          glGetQueryObjectui64v(queries[0], GL_QUERY_RESULT, &generated);
          glGetQueryObjectui64v(queries[1], GL_QUERY_RESULT, &written);
          check("capturing triangles");
          ++passes;
          // The draw (classification and emission) and the capture's copy to the CPU.
          const StageClock::Mark drawn = device_mark(clock);
          const StageClock::Mark read_start = cpu_mark(clock);
          staging.resize(written * 3 * words);
          capture.read(0, written * tri_bytes, staging.data());
          if (clock) {
            clock->add(GlStage::Classify, draw_start, drawn);
            clock->add_wait(GlStage::Readback, drawn, read_start, StageClock::cpu_mark());
          }
          auto cell_of = [&](std::uint64_t t) { return staging[t * 3 * words + 1]; };
          const CaptureCut cut =
              cut_capture(static_cast<std::uint64_t>(first), static_cast<std::uint64_t>(n_cells),
                          written, generated, cell_of);
          const std::uint64_t keep = cut.keep;
          const std::int64_t resume = static_cast<std::int64_t>(cut.resume);
          if (written < generated) {
            const std::uint64_t needed = generated - keep;
            if (needed > cap) {
              cap = std::min(needed, limit);
              capture = Buffer(cap * tri_bytes);
            }
          }
          const std::size_t base = soup.keys.size();
          soup.keys.resize(base + 3 * keep);
          soup.positions.resize(base + 3 * keep);
          soup.in_box.resize(base / 3 + keep);
          if (o.normals) soup.normals.resize(base + 3 * keep);
          const Index3 dc = {cells.extent(0), cells.extent(1), cells.extent(2)};
          for (std::size_t t = 0; t < keep; ++t) {
            const std::int64_t c = cell_of(t);
            soup.in_box[base / 3 + t] = cells.lo[0] + c % dc[0] < box.hi[0] &&
                                        cells.lo[1] + (c / dc[0]) % dc[1] < box.hi[1] &&
                                        cells.lo[2] + c / (dc[0] * dc[1]) < box.hi[2];
          }
          for (std::size_t c = 0; c < 3 * keep; ++c) {
            const std::uint32_t* w = staging.data() + c * words;
            const std::uint64_t e = w[0] / 3, axis = w[0] % 3;
            const std::int64_t sx = cells.lo[0] + static_cast<std::int64_t>(e % d[0]);
            const std::int64_t sy = cells.lo[1] + static_cast<std::int64_t>((e / d[0]) % d[1]);
            const std::int64_t sz = cells.lo[2] + static_cast<std::int64_t>(e / (d[0] * d[1]));
            const std::uint64_t lin = static_cast<std::uint64_t>(
                sx + view.global_dims[0] * (sy + view.global_dims[1] * sz));
            soup.keys[base + c] = lin * 3 + axis;
            std::memcpy(soup.positions[base + c].data(), w + 2, 12);
            if (o.normals) std::memcpy(soup.normals[base + c].data(), w + 5, 12);
          }
          first = resume;
        }
        progress_advance(o.progress);  // Stage::Extract, begun below the slabs' plan
      }
    } catch (...) {
      glDisable(GL_RASTERIZER_DISCARD);
      glDeleteQueries(2, queries);
      throw;
    }
    glDisable(GL_RASTERIZER_DISCARD);
    glDeleteQueries(2, queries);
    glUseProgram(0);

    // The weld runs on the CPU: counted, in wall seconds, as the face stage.
    const auto weld_start = std::chrono::steady_clock::now();
    // Weld: corners sorted by (key, position in the soup); one vertex per distinct key whose lower
    // sample lies in the closed box, in key order. Every such crossed edge borders a drawn cell, so
    // these are exactly the CPU's vertices.
    const std::size_t n = soup.keys.size();
    std::vector<std::pair<std::uint64_t, std::uint32_t>> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = {soup.keys[i], static_cast<std::uint32_t>(i)};
    tbb::parallel_sort(order.begin(), order.end());
    auto in_closed_box = [&](std::uint64_t key) {
      const std::uint64_t lin = key / 3;
      const auto nx = static_cast<std::uint64_t>(view.global_dims[0]);
      const auto ny = static_cast<std::uint64_t>(view.global_dims[1]);
      const std::int64_t s[3] = {static_cast<std::int64_t>(lin % nx),
                                 static_cast<std::int64_t>((lin / nx) % ny),
                                 static_cast<std::int64_t>(lin / (nx * ny))};
      for (int a = 0; a < 3; ++a)
        if (s[a] < box.lo[a] || s[a] > box.hi[a]) return false;
      return true;
    };
    std::vector<std::uint32_t> vertex_of(n, ~0u);
    for (std::size_t i = 0; i < n; ++i) {
      if (!in_closed_box(order[i].first)) continue;
      if (i == 0 || order[i].first != order[i - 1].first) {
        if (mesh.positions.size() == std::numeric_limits<std::uint32_t>::max())
          throw CapacityError(
              "the mesh would have more than 2^32 - 1 vertices, more than an "
              "in-memory mesh can index");
        mesh.positions.push_back(soup.positions[order[i].second]);
        if (o.normals) mesh.normals.push_back(soup.normals[order[i].second]);
      }
      vertex_of[order[i].second] = static_cast<std::uint32_t>(mesh.positions.size() - 1);
    }
    mesh.triangles.reserve(n / 3);
    for (std::size_t t = 0; t < n / 3; ++t)
      if (soup.in_box[t])
        mesh.triangles.push_back({vertex_of[3 * t], vertex_of[3 * t + 1], vertex_of[3 * t + 2]});
    if (stats) {
      // Taken before collect(), which reads the timer queries: that wait is no part of the weld.
      const double weld_seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - weld_start).count();
      stats->times = clock->collect();
      stats->times[GlStage::Faces] += weld_seconds;
      stats->bricks = static_cast<int>(slabs.size());
      stats->capture_passes = passes;
      stats->early_uploads = early;
    }
    return mesh;
  });
}

}  // namespace isotile::gl
