// Dual Contouring on the geometry-shader path (the paper's Sec. IV-A for DC): the dual vertices
// come from the compute pass both paths share (dc_histopyramid.cpp); the faces from a geometry
// shader over the slab's vertex cells that emits, per cell, the quads of its lower corner's
// edges as triangle pairs split by the CPU's diagonal rule (or as four points each with
// --quads), captured by transform feedback as vertex indices. Transform feedback keeps primitive
// order, so the faces come out in the CPU's order.
//
// Capture limits as in mc_geometry_shader.cpp: at most 2 GiB per binding; an overflow (written <
// generated) drops the last element's faces, possibly cut short, and resumes the draw there.
#include <algorithm>
#include <cstring>
#include <vector>

#include "core/errors.h"
#include "dc_gl.h"
#include "dc_gl_shared.h"
#include "gl_context.h"
#include "gl_program.h"

namespace isotile::gl {

namespace {
constexpr std::uint64_t kMaxCaptureBytes = std::uint64_t{1} << 31;
}  // namespace

int dc_gs_faces(const std::string& defines, const std::function<void(GLuint)>& uniforms,
                const Pyramid& pyr, std::uint64_t elements, std::uint64_t n_quads, bool keep_quads,
                std::uint64_t capture_bytes, std::uint32_t* out) {
  // A primitive: a triangle (3 corners) or, with quads, a point; a corner: vertex, element.
  const std::uint64_t corners = keep_quads ? 1 : 3;
  const std::uint64_t per_quad = keep_quads ? 4 : 2;  // primitives
  const std::uint64_t prim_bytes = corners * 8;
  // One element's faces (three quads) and one more primitive always fit, so that an overflow
  // always keeps at least the first element drawn.
  const std::uint64_t limit = std::max<std::uint64_t>(
      std::min(capture_bytes, kMaxCaptureBytes) / prim_bytes, 3 * per_quad + 1);
  const std::uint64_t total = n_quads * per_quad;
  std::uint64_t cap = std::min(limit, total);

  const GLuint vao = empty_vertex_array();
  const GLuint prog =
      program({{GL_VERTEX_SHADER, "dc_gs.vert"}, {GL_GEOMETRY_SHADER, "dc_gs.geom"}}, defines,
              {"tf_vertex", "tf_elem"});
  uniforms(prog);
  pyr.set_uniforms(prog);
  GLuint queries[2];
  glCreateQueries(GL_PRIMITIVES_GENERATED, 1, &queries[0]);
  glCreateQueries(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, 1, &queries[1]);
  glEnable(GL_RASTERIZER_DISCARD);
  glBindVertexArray(vao);
  glUseProgram(prog);
  int passes = 0;
  std::uint64_t done = 0;  // primitives kept
  std::vector<std::uint32_t> staging;
  try {
    Buffer capture(cap * prim_bytes);
    for (std::uint64_t first = 0; first < elements;) {
      glBindBufferRange(GL_TRANSFORM_FEEDBACK_BUFFER, 0, capture.id(), 0,
                        static_cast<GLsizeiptr>(cap * prim_bytes));
      glBeginQuery(GL_PRIMITIVES_GENERATED, queries[0]);
      glBeginQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, queries[1]);
      glBeginTransformFeedback(keep_quads ? GL_POINTS : GL_TRIANGLES);
      glDrawArrays(GL_POINTS, static_cast<GLint>(first), static_cast<GLsizei>(elements - first));
      glEndTransformFeedback();
      glEndQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN);
      glEndQuery(GL_PRIMITIVES_GENERATED);
      GLuint64 generated = 0, written = 0;
      glGetQueryObjectui64v(queries[0], GL_QUERY_RESULT, &generated);
      glGetQueryObjectui64v(queries[1], GL_QUERY_RESULT, &written);
      check("capturing Dual Contouring faces");
      ++passes;
      staging.resize(written * corners * 2);
      capture.read(0, written * prim_bytes, staging.data());
      auto elem_of = [&](std::uint64_t p) { return staging[p * corners * 2 + 1]; };
      const auto [keep, resume] = cut_capture(first, elements, written, generated, elem_of);
      if (written < generated) {
        const std::uint64_t needed = generated - keep;
        if (needed > cap) {
          cap = std::min(needed, limit);
          capture = Buffer(cap * prim_bytes);
        }
      }
      if (done + keep > total) throw Error("transform feedback captured more faces than counted");
      for (std::uint64_t c = 0; c < keep * corners; ++c) out[done * corners + c] = staging[2 * c];
      done += keep;
      first = resume;
    }
  } catch (...) {
    glDisable(GL_RASTERIZER_DISCARD);
    glDeleteQueries(2, queries);
    throw;
  }
  glDisable(GL_RASTERIZER_DISCARD);
  glDeleteQueries(2, queries);
  if (done != total) throw Error("transform feedback captured fewer faces than counted");
  return passes;
}

Mesh dc_geometry_shader(const VolumeView& view, const DcGlOptions& o, McStats* stats) {
  return dc_extract_gl(view, o, stats, true);
}

}  // namespace isotile::gl
