#include "mesh_render.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <limits>
#include <vector>

#include "colour_ramp.h"
#include "core/errors.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/ply_face_stream.h"
#include "gl_context.h"
#include "gl_program.h"

namespace isotile::gl {

namespace {

using V3 = std::array<double, 3>;

V3 sub(const V3& a, const V3& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
double dot(const V3& a, const V3& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
V3 cross(const V3& a, const V3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
V3 normalized(const V3& a) {
  const double n = std::sqrt(dot(a, a));
  return n > 0 ? V3{a[0] / n, a[1] / n, a[2] / n} : V3{0, 0, 0};
}
V3 to_v3(const Vec3f& p) {
  return {p[0], p[1], p[2]};
}

// The camera's frame: `back` points from the scene to the camera, `right` and `up` span the
// picture. At the poles (elevation +-90) `right` follows the azimuth.
struct Camera {
  V3 back, right, up;
};
Camera camera(double azimuth_deg, double elevation_deg) {
  const double az = azimuth_deg * M_PI / 180, el = elevation_deg * M_PI / 180;
  Camera c;
  c.back = {std::cos(el) * std::sin(az), -std::cos(el) * std::cos(az), std::sin(el)};
  const V3 forward = {-c.back[0], -c.back[1], -c.back[2]};
  c.right = std::abs(std::cos(el)) < 1e-9 ? V3{std::cos(az), std::sin(az), 0}
                                          : normalized(cross(forward, {0, 0, 1}));
  c.up = cross(c.right, forward);
  return c;
}

// The framebuffer, its renderbuffers and the vertex array of one render call, deleted (and the
// context's own framebuffer bound again) when the call ends, however it ends.
struct Target {
  GLuint framebuffer = 0, colour = 0, depth = 0, vertex_array = 0;
  GLint previous = 0;
  Target(int w, int h) {
    glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous);
    glCreateRenderbuffers(1, &colour);
    glNamedRenderbufferStorage(colour, GL_RGBA8, w, h);
    glCreateRenderbuffers(1, &depth);
    glNamedRenderbufferStorage(depth, GL_DEPTH_COMPONENT32F, w, h);
    glCreateFramebuffers(1, &framebuffer);
    glNamedFramebufferRenderbuffer(framebuffer, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour);
    glNamedFramebufferRenderbuffer(framebuffer, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
    glCreateVertexArrays(1, &vertex_array);
  }
  ~Target() {
    glDisable(GL_DEPTH_TEST);
    glBindVertexArray(0);
    glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(previous));
    glDeleteVertexArrays(1, &vertex_array);
    glDeleteFramebuffers(1, &framebuffer);
    glDeleteRenderbuffers(1, &depth);
    glDeleteRenderbuffers(1, &colour);
  }
  Target(const Target&) = delete;
  Target& operator=(const Target&) = delete;
};

constexpr int kFloatsPerCorner = 8;  // position - centre, quality, normal, padding
constexpr std::uint64_t kBytesPerTriangle = 3 * kFloatsPerCorner * sizeof(float);

}  // namespace

std::vector<Stage> render_stages() {
  return {{GL_VERTEX_SHADER, "render_mesh.vert"}, {GL_FRAGMENT_SHADER, "render_mesh.frag"}};
}

std::string render_defines(RenderColour colour, bool wireframe) {
  std::string d = "#define RAMP_SIZE " + std::to_string(kQualityRampSize) + "\n";
  d += colour == RenderColour::Quality  ? "#define COLOUR_QUALITY\n"
       : colour == RenderColour::Normal ? "#define COLOUR_NORMAL\n"
                                        : "#define COLOUR_SOLID\n";
  if (wireframe) d += "#define WIREFRAME\n";
  return d;
}

void parse_view(const std::string& view, RenderOptions& o) {
  struct Named {
    const char* name;
    double azimuth, elevation;
  };
  static constexpr Named kViews[] = {{"iso", 45, 35.264389682754654},
                                     {"front", 0, 0},
                                     {"back", 180, 0},
                                     {"right", 90, 0},
                                     {"side", 90, 0},
                                     {"left", -90, 0},
                                     {"top", 0, 90},
                                     {"bottom", 0, -90}};
  for (const Named& n : kViews)
    if (view == n.name) {
      o.azimuth = n.azimuth;
      o.elevation = n.elevation;
      return;
    }
  const std::size_t comma = view.find(',');
  if (comma != std::string::npos) {
    const std::string a = view.substr(0, comma), e = view.substr(comma + 1);
    char *end_a = nullptr, *end_e = nullptr;
    const double az = std::strtod(a.c_str(), &end_a), el = std::strtod(e.c_str(), &end_e);
    if (!a.empty() && !e.empty() && *end_a == '\0' && *end_e == '\0' && std::isfinite(az) &&
        std::isfinite(el) && el >= -90 && el <= 90) {
      o.azimuth = az;
      o.elevation = el;
      return;
    }
  }
  throw InputError(
      "--view must be iso, front, back, left, right, side, top, bottom or "
      "AZIMUTH,ELEVATION in degrees (elevation in [-90, 90]), got '" +
      view + "'");
}

namespace {

// Appends the triangles that follow to `out` until it holds at least `max` or they end.
using NextTriangles = std::function<void(std::size_t max, std::vector<Tri>& out)>;

// Draws the triangles `next` gives (indices into `positions`, already checked); `expected`, the
// number of triangles or faces to come, only sizes the vertex buffer.
Picture render_pieces(const std::vector<Vec3f>& positions, std::uint64_t expected,
                      const NextTriangles& next, const RenderOptions& o, RenderStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  if (o.width < 1 || o.height < 1)
    throw InputError("the picture size must be at least 1x1, got " + std::to_string(o.width) + "x" +
                     std::to_string(o.height));
  if (!(o.zoom > 0) || !std::isfinite(o.zoom)) throw InputError("--zoom must be a positive number");
  if (o.center && !(std::isfinite((*o.center)[0]) && std::isfinite((*o.center)[1]) &&
                    std::isfinite((*o.center)[2])))
    throw InputError("--center must be three finite numbers");
  if (!std::isfinite(o.azimuth) || !(o.elevation >= -90 && o.elevation <= 90))
    throw InputError("the view's azimuth must be finite and its elevation in [-90, 90]");
  const int bar = o.colour == RenderColour::Quality ? colour_bar_height(o.width, o.height) : 0;
  if (bar > 0 && (o.height - bar < 8 || o.width < 64))
    throw InputError("a picture coloured by quality needs at least 64x" + std::to_string(bar + 8) +
                     " pixels for its colour bar, got " + std::to_string(o.width) + "x" +
                     std::to_string(o.height));

  // Bounding box of every vertex (all must be finite).
  V3 lo = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
           std::numeric_limits<double>::infinity()};
  V3 hi = {-lo[0], -lo[1], -lo[2]};
  for (std::size_t i = 0; i < positions.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      const double v = positions[i][a];
      if (!std::isfinite(v))
        throw InputError("vertex " + std::to_string(i) + " has a non-finite coordinate");
      lo[a] = std::min(lo[a], v);
      hi[a] = std::max(hi[a], v);
    }
  if (positions.empty()) lo = hi = {0, 0, 0};

  Scope scope;  // throws InputError naming why when there is no context
  GLint max_renderbuffer = 0, max_viewport[2] = {};
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_renderbuffer);
  glGetIntegerv(GL_MAX_VIEWPORT_DIMS, max_viewport);
  const int limit = std::min({max_renderbuffer, max_viewport[0], max_viewport[1]});
  if (o.width > limit || o.height > limit)
    throw InputError("the picture size " + std::to_string(o.width) + "x" +
                     std::to_string(o.height) + " exceeds the device's largest, " +
                     std::to_string(limit) + "x" + std::to_string(limit));

  // Framing: orthographic; the vertices projected onto the picture plane fit the view (less the
  // margin), then magnified by the zoom about the centre. The default centre is the middle of
  // the projected extent (and of the depth range), so the mesh fills the picture whatever the
  // view; a given centre keeps its place and the scale fits the farthest vertex from it.
  const Camera cam = camera(o.azimuth, o.elevation);
  V3 centre =
      o.center ? *o.center : V3{(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2};
  double xmin = 0, xmax = 0, ymin = 0, ymax = 0, dmin = 0, dmax = 0;
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const V3 p = sub(to_v3(positions[i]), centre);
    const double x = dot(p, cam.right), y = dot(p, cam.up), d = -dot(p, cam.back);
    if (i == 0) xmin = xmax = x, ymin = ymax = y, dmin = dmax = d;
    xmin = std::min(xmin, x), xmax = std::max(xmax, x);
    ymin = std::min(ymin, y), ymax = std::max(ymax, y);
    dmin = std::min(dmin, d), dmax = std::max(dmax, d);
  }
  double hx = std::max(std::abs(xmin), std::abs(xmax)),
         hy = std::max(std::abs(ymin), std::abs(ymax));
  if (!o.center) {
    const double xmid = (xmin + xmax) / 2, ymid = (ymin + ymax) / 2;
    for (int a = 0; a < 3; ++a) centre[a] += cam.right[a] * xmid + cam.up[a] * ymid;
    hx = (xmax - xmin) / 2;
    hy = (ymax - ymin) / 2;
  }
  const int view_h = o.height - bar;
  double scale = std::numeric_limits<double>::infinity();  // pixels per unit
  if (hx > 0) scale = std::min(scale, o.width / (2 * hx));
  if (hy > 0) scale = std::min(scale, view_h / (2 * hy));
  if (!std::isfinite(scale)) scale = 1;
  scale *= (1 - 2 * kRenderMargin) * o.zoom;
  const double pad = (dmax - dmin) * 0.01 + 1e-6 * (1 + std::abs(dmin) + std::abs(dmax));
  const double zmid = (dmin + dmax) / 2, zhalf = (dmax - dmin) / 2 + pad;
  const double sx = scale / (o.width / 2.0), sy = scale / (view_h / 2.0), sz = 1 / zhalf;
  // Positions go to the device as (p - centre) / unit, in double on the CPU, so that the floats
  // on the device and the matrix's entries stay near 1 whatever the mesh's size: sent as they
  // were, a mesh 1e38 across gave entries below float's normal range (flushed to zero: a blank
  // picture) and one 1e-38 across flushed its own coordinates.
  const double unit = std::max({hx, hy, zhalf}) > 0 ? std::max({hx, hy, zhalf}) : 1.0;
  // Column-major: row 0 = right * sx, row 1 = up * sy, row 2 = forward * sz - zmid * sz.
  float m[16] = {};
  for (int a = 0; a < 3; ++a) {
    m[a * 4 + 0] = static_cast<float>(cam.right[a] * sx * unit);
    m[a * 4 + 1] = static_cast<float>(cam.up[a] * sy * unit);
    m[a * 4 + 2] = static_cast<float>(-cam.back[a] * sz * unit);
  }
  m[14] = static_cast<float>(-zmid * sz);
  m[15] = 1;

  const std::string defines = render_defines(o.colour, o.wireframe);
  const GLuint prog = program(render_stages(), defines);
  glProgramUniformMatrix4fv(prog, glGetUniformLocation(prog, "u_view_proj"), 1, GL_FALSE, m);
  const float to_camera[3] = {static_cast<float>(cam.back[0]), static_cast<float>(cam.back[1]),
                              static_cast<float>(cam.back[2])};
  glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_to_camera"), 1, to_camera);
  float ramp[kQualityRampSize * 3];
  for (int i = 0; i < kQualityRampSize; ++i)
    for (int k = 0; k < 3; ++k) ramp[i * 3 + k] = kQualityRamp[i][k] / 255.0f;
  if (o.colour == RenderColour::Quality)
    glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_ramp"), kQualityRampSize, ramp);
  const float solid[3] = {0.72f, 0.76f, 0.82f};
  if (o.colour == RenderColour::Solid)
    glProgramUniform3fv(prog, glGetUniformLocation(prog, "u_solid"), 1, solid);

  Target target(o.width, o.height);
  if (glCheckNamedFramebufferStatus(target.framebuffer, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw Error("the device cannot render into an RGBA8 + depth framebuffer");
  glBindFramebuffer(GL_FRAMEBUFFER, target.framebuffer);
  glViewport(0, 0, o.width, o.height);
  glClearColor(1, 1, 1, 1);
  glClearDepth(1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glViewport(0, bar, o.width, view_h);  // the colour bar's band stays clear
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glUseProgram(prog);
  glBindVertexArray(target.vertex_array);
  check("preparing to render");

  // The triangles, piece by piece; their quality's min, max and sum in drawing order.
  const std::uint64_t per_piece = std::max<std::uint64_t>(
      1, o.piece_triangles ? o.piece_triangles : kRenderPieceBytes / kBytesPerTriangle);
  const std::uint64_t piece = std::min(per_piece, std::max<std::uint64_t>(expected, 1));
  Buffer vertices(piece * kBytesPerTriangle, nullptr, GL_DYNAMIC_STORAGE_BIT);
  glVertexArrayVertexBuffer(target.vertex_array, 0, vertices.id(), 0,
                            kFloatsPerCorner * sizeof(float));
  for (GLuint attr = 0; attr < 2; ++attr) {
    glEnableVertexArrayAttrib(target.vertex_array, attr);
    glVertexArrayAttribFormat(target.vertex_array, attr, 4, GL_FLOAT, GL_FALSE,
                              attr * 4 * sizeof(float));
    glVertexArrayAttribBinding(target.vertex_array, attr, 0);
  }
  std::vector<float> host(piece * 3 * kFloatsPerCorner);
  std::vector<double> quality(piece);
  std::vector<Tri> tris;
  std::uint64_t pieces = 0, drawn = 0;
  double qmin = 1, qmax = 0, qsum = 0;
  for (;;) {
    tris.clear();
    next(piece, tris);
    if (tris.empty()) break;
    // `next` may overshoot by a polygon's fan: its triangles go in a piece of their own.
    for (std::size_t first = 0; first < tris.size(); first += piece) {
      const std::size_t count = std::min<std::size_t>(piece, tris.size() - first);
      tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) {
        const Tri& idx = tris[first + i];
        const Vec3f& a = positions[idx[0]];
        const Vec3f& b = positions[idx[1]];
        const Vec3f& c = positions[idx[2]];
        quality[i] = radius_ratio(a, b, c);
        const V3 n = normalized(cross(sub(to_v3(b), to_v3(a)), sub(to_v3(c), to_v3(a))));
        float* out = host.data() + i * 3 * kFloatsPerCorner;
        for (int k = 0; k < 3; ++k, out += kFloatsPerCorner) {
          const V3 p = sub(to_v3(positions[idx[k]]), centre);
          out[0] = static_cast<float>(p[0] / unit);
          out[1] = static_cast<float>(p[1] / unit);
          out[2] = static_cast<float>(p[2] / unit);
          out[3] = static_cast<float>(quality[i]);
          out[4] = static_cast<float>(n[0]);
          out[5] = static_cast<float>(n[1]);
          out[6] = static_cast<float>(n[2]);
          out[7] = 0;
        }
      });
      for (std::size_t i = 0; i < count; ++i) {
        qmin = std::min(qmin, quality[i]);
        qmax = std::max(qmax, quality[i]);
        qsum += quality[i];
      }
      glNamedBufferSubData(vertices.id(), 0, static_cast<GLsizeiptr>(count * kBytesPerTriangle),
                           host.data());
      glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(count * 3));
      check("drawing a piece of the mesh");
      ++pieces;
      drawn += count;
    }
  }

  std::vector<std::uint8_t> rgba(std::size_t(o.width) * o.height * 4);
  glReadPixels(0, 0, o.width, o.height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  check("reading the picture back");

  Picture pic;
  pic.width = o.width;
  pic.height = o.height;
  pic.rgb.resize(std::size_t(o.width) * o.height * 3);
  for (int y = 0; y < o.height; ++y) {  // GL's first row is the bottom one
    const std::uint8_t* src = rgba.data() + std::size_t(o.height - 1 - y) * o.width * 4;
    std::uint8_t* dst = pic.rgb.data() + std::size_t(y) * o.width * 3;
    for (int x = 0; x < o.width; ++x)
      for (int k = 0; k < 3; ++k) dst[x * 3 + k] = src[x * 4 + k];
  }

  RenderStats s;
  s.triangles = drawn;
  s.pieces = pieces;
  if (drawn > 0) {
    s.quality_min = qmin;
    s.quality_mean = qsum / static_cast<double>(drawn);
    s.quality_max = qmax;
  }
  if (o.colour == RenderColour::Quality)
    draw_colour_bar(pic, s.quality_min, s.quality_mean, s.quality_max, drawn);
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (stats) *stats = s;
  return pic;
}

}  // namespace

Picture render_mesh(const Mesh& mesh, const RenderOptions& o, RenderStats* stats) {
  check_face_indices(mesh);
  const std::uint64_t ntri = mesh.triangles.size(), total = ntri + 2 * mesh.quads.size();
  std::uint64_t t = 0;
  const NextTriangles next = [&](std::size_t max, std::vector<Tri>& out) {
    for (; t < total && out.size() < max; ++t) {
      if (t < ntri) {
        out.push_back(mesh.triangles[t]);
      } else {
        const Quad& q = mesh.quads[(t - ntri) / 2];
        out.push_back((t - ntri) % 2 == 0 ? Tri{q[0], q[1], q[2]} : Tri{q[0], q[2], q[3]});
      }
    }
  };
  return render_pieces(mesh.positions, total, next, o, stats);
}

Picture render_mesh_file(const std::filesystem::path& path, const RenderOptions& o,
                         RenderStats* stats) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".ply")
    if (std::optional<PlyFaceStream> ply = PlyFaceStream::open(path)) {
      const NextTriangles next = [&](std::size_t max, std::vector<Tri>& out) {
        ply->next(max, out);
      };
      return render_pieces(ply->positions(), ply->faces(), next, o, stats);
    }
  return render_mesh(read_mesh(path), o, stats);
}

}  // namespace isotile::gl
