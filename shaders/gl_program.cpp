#include "gl_program.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <string_view>

#include "core/errors.h"
#include "core/extract/macet_table.h"
#include "core/extract/marching_cubes_tables.h"
#include "gl_context.h"
#include "program_cache.h"
#include "read_back.h"

namespace isotile::gl {

void check(const char* where) {
  const GLenum e = glGetError();
  if (e == GL_NO_ERROR) return;
  char buf[128];
  std::snprintf(buf, sizeof buf, "OpenGL error 0x%04x in %s", e, where);
  if (e == GL_OUT_OF_MEMORY)
    // Said for both of its callers: render has no --memory (llvmpipe's device memory is the
    // process's, which ulimit -v bounds).
    throw CapacityError(std::string(buf) +
                        " (device memory exhausted: extract with a smaller --memory, or render a "
                        "smaller --size)");
  throw Error(buf);
}

namespace {

// Hands the wall seconds of its scope to `add` when it ends, on every way out.
template <class Add>
struct Timed {
  Add add;
  std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  ~Timed() { add(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()); }
};

// Programs live until shutdown(); every key built is remembered for the variant check.
std::map<std::string, GLuint>& program_cache() {
  static std::map<std::string, GLuint> cache;
  return cache;
}
std::vector<std::string>& built_keys() {
  static std::vector<std::string> keys;
  return keys;
}
std::unique_ptr<Buffer>& case_tables(CaseTable which) {
  static std::unique_ptr<Buffer> mc_tables, macet_tables;
  return which == CaseTable::Macet ? macet_tables : mc_tables;
}
GLuint& vertex_array() {
  static GLuint vao = 0;
  return vao;
}

}  // namespace

std::string glsl_double(double v) {
  std::uint64_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  char buf[64];
  std::snprintf(buf, sizeof buf, "packDouble2x32(uvec2(0x%08xu, 0x%08xu))",
                static_cast<unsigned>(bits & 0xffffffffu), static_cast<unsigned>(bits >> 32));
  return buf;
}

std::string stage_source(const Stage& s, const std::string& defines) {
  std::string src = "#version 450 core\n";
  // `isotile render`'s vertex and fragment stages stand alone: mc_common.glsl is the extractors'.
  if (s.file.starts_with("render_")) {
    src += defines;
    src += "#line 1\n";
    src += embedded_glsl(s.file);
    return src;
  }
  if (s.type == GL_COMPUTE_SHADER) src += "#define STAGE_COMPUTE\n";
  src += defines;
  // The correctly rounded double square root every extractor's roots go through (its own
  // line numbers, so that mc_common.glsl's and the stage's keep theirs after #line).
  src += embedded_glsl("sqrt_rn.glsl");
  src += "#line 1\n";
  src += embedded_glsl("mc_common.glsl");
  // Dual Contouring's shaders share its Hermite data and placement; its output passes the
  // HistoPyramid traversal (vertex indices) and its face passes the quads' corners and diagonal.
  const bool dc = s.file.starts_with("dc_");
  if (dc) src += embedded_glsl("dc_common.glsl");
  // HistoPyramid output passes share the traversal.
  if ((s.file.starts_with("hp_") && s.file != "hp_classify.comp" && s.file != "hp_reduce.comp") ||
      (dc && s.file != "dc_hp_classify.comp" && s.file != "dc_gs.vert"))
    src += embedded_glsl("hp_common.glsl");
  if (s.file == "dc_hp_quads.comp" || s.file == "dc_gs.geom") src += embedded_glsl("dc_faces.glsl");
  // Macet's field, root finding and vertex (shaders/macet_gl.cpp defines MACET), and its moves.
  if (defines.find("#define MACET\n") != std::string::npos)
    src += embedded_glsl("macet_common.glsl");
  if (s.file == "macet_push.comp" || s.file == "macet_smooth.comp" || s.file == "macet_linear.comp")
    src += embedded_glsl("macet_move.glsl");
  const std::string_view body = embedded_glsl(s.file);
  if (body.empty()) throw Error("GLSL file " + std::string(s.file) + " is not embedded");
  src += body;
  // The output passes' main() calls the pass's emit_output(), defined in its body.
  if (s.file == "hp_vertices.comp" || s.file == "hp_triangles.comp" ||
      s.file == "dc_hp_vertices.comp" || s.file == "dc_hp_quads.comp")
    src += embedded_glsl("hp_output.glsl");
  return src;
}

std::string program_key(const std::vector<Stage>& stages, const std::string& defines) {
  std::string key = defines;
  for (const Stage& s : stages) {
    key += '|';  // appended piecewise: GCC 12 warns (-Wrestrict) on "|" + std::string
    key += s.file;
  }
  return key;
}

std::vector<std::string> built_program_keys() {
  return built_keys();
}

void release_programs() {
  for (auto& [key, prog] : program_cache()) glDeleteProgram(prog);
  program_cache().clear();
  case_tables(CaseTable::MarchingCubes).reset();
  case_tables(CaseTable::Macet).reset();
  if (vertex_array()) glDeleteVertexArrays(1, &vertex_array());
  vertex_array() = 0;
}

GLuint empty_vertex_array() {
  if (!vertex_array()) {
    at_shutdown(release_programs);
    glCreateVertexArrays(1, &vertex_array());
  }
  return vertex_array();
}

namespace {

// A driver's info log as one line of a message: its lines joined by "; ", no trailing newline
// (Mesa's and NVIDIA's logs end with one, and have a line per error).
std::string one_line(const char* log) {
  std::string out;
  std::string_view rest = log;
  while (!rest.empty()) {
    const std::size_t end = std::min(rest.find('\n'), rest.size());
    std::string_view line = rest.substr(0, end);
    while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back())))
      line.remove_suffix(1);
    if (!line.empty()) out += (out.empty() ? "" : "; ") + std::string(line);
    rest.remove_prefix(std::min(end + 1, rest.size()));
  }
  return out;
}

GLuint compile(const Stage& s, const std::string& src) {
  const GLuint sh = glCreateShader(s.type);
  const char* text = src.c_str();
  glShaderSource(sh, 1, &text, nullptr);
  glCompileShader(sh);
  GLint ok = 0;
  glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096] = {};
    glGetShaderInfoLog(sh, sizeof log, nullptr, log);
    glDeleteShader(sh);
    throw Error("compiling " + std::string(s.file) + " failed: " + one_line(log));
  }
  return sh;
}

}  // namespace

GLuint program(const std::vector<Stage>& stages, const std::string& defines,
               const std::vector<const char*>& varyings) {
  auto& cache = program_cache();
  const std::string key = program_key(stages, defines);
  if (auto it = cache.find(key); it != cache.end()) return it->second;
  const Timed timed{count_program_seconds};  // for --stats (seconds.gl.programs)
  at_shutdown(release_programs);
  // The on-disk cache's key (program_cache.h): every stage's full source and the varyings.
  std::vector<std::string> sources;
  std::string disk_key = "isotile program 1\n";
  for (const Stage& s : stages) {
    sources.push_back(stage_source(s, defines));
    disk_key += "stage " + std::to_string(s.type) + " " + std::string(s.file) + "\n";
    disk_key += sources.back();
    disk_key += '\n';
  }
  for (const char* v : varyings) {
    disk_key += "varying ";
    disk_key += v;
    disk_key += '\n';
  }
  if (const GLuint saved = load_program(disk_key)) {
    check("loading a saved program");
    cache.emplace(key, saved);
    built_keys().push_back(key);
    return saved;
  }
  count_compiled_program();
  const GLuint prog = glCreateProgram();
  std::vector<GLuint> shaders;
  for (std::size_t i = 0; i < stages.size(); ++i) {
    shaders.push_back(compile(stages[i], sources[i]));
    glAttachShader(prog, shaders.back());
  }
  if (!varyings.empty())
    glTransformFeedbackVaryings(prog, static_cast<GLsizei>(varyings.size()), varyings.data(),
                                GL_INTERLEAVED_ATTRIBS);
  if (program_cache_enabled())
    glProgramParameteri(prog, GL_PROGRAM_BINARY_RETRIEVABLE_HINT, GL_TRUE);
  glLinkProgram(prog);
  for (GLuint sh : shaders) glDeleteShader(sh);
  GLint ok = 0;
  glGetProgramiv(prog, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096] = {};
    glGetProgramInfoLog(prog, sizeof log, nullptr, log);
    glDeleteProgram(prog);
    throw Error("linking " + std::string(stages.front().file) + " failed: " + one_line(log));
  }
  check("linking a program");
  store_program(disk_key, prog);
  cache.emplace(key, prog);
  built_keys().push_back(key);
  return prog;
}

Buffer::Buffer(std::size_t bytes, const void* data, GLbitfield flags) : bytes_(bytes) {
  glCreateBuffers(1, &id_);
  glNamedBufferStorage(id_, static_cast<GLsizeiptr>(std::max<std::size_t>(bytes, 4)), data, flags);
  check("allocating a buffer");
}

Buffer::~Buffer() {
  if (id_) glDeleteBuffers(1, &id_);
}

Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    if (id_) glDeleteBuffers(1, &id_);
    id_ = o.id_;
    bytes_ = o.bytes_;
    o.id_ = 0;
  }
  return *this;
}

void Buffer::bind(GLenum target, GLuint index) const {
  glBindBufferRange(target, index, id_, 0,
                    static_cast<GLsizeiptr>(std::max<std::size_t>(bytes_, 4)));
}

void Buffer::read(std::size_t offset, std::size_t bytes, void* out) const {
  read_back(id_, offset, bytes, out);
}

namespace {
double g_mapped_seconds = 0;  // mapped_buffer_seconds(); with the context current
}  // namespace

double mapped_buffer_seconds() {
  return g_mapped_seconds;
}

void MappedBuffer::create(std::size_t size, GLbitfield access, const char* what) {
  const Timed timed{[](double seconds) { g_mapped_seconds += seconds; }};
  const GLbitfield map = access | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
  bytes = size;
  glCreateBuffers(1, &id);
  glNamedBufferStorage(id, static_cast<GLsizeiptr>(size), nullptr, map | GL_CLIENT_STORAGE_BIT);
  mapped =
      static_cast<std::byte*>(glMapNamedBufferRange(id, 0, static_cast<GLsizeiptr>(size), map));
  if (!mapped) {
    glDeleteBuffers(1, &id);
    *this = {};
    check((std::string("mapping ") + what).c_str());
    throw Error(std::string("OpenGL could not map ") + what);
  }
}

bool MappedBuffer::ensure(std::size_t at_least, GLbitfield access, const char* what) {
  if (id && bytes >= at_least) return false;
  wait();
  release();
  create(at_least, access, what);
  return true;
}

std::size_t bytes_held(std::span<const MappedBuffer> buffers) {
  std::size_t sum = 0;
  for (const MappedBuffer& b : buffers) sum += b.bytes;
  return sum;
}

std::size_t mapped_bytes_for(std::size_t need, std::size_t piece) {
  return std::min(piece, std::bit_ceil(std::max(need, kMinMappedBytes)));
}

void MappedBuffer::release() {
  if (fence) glDeleteSync(fence);
  if (id) {
    glUnmapNamedBuffer(id);
    glDeleteBuffers(1, &id);
  }
  *this = {};
}

void MappedBuffer::fence_commands() {
  if (fence) glDeleteSync(fence);
  fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
}

void MappedBuffer::wait() {
  if (!fence) return;
  while (glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, 1'000'000'000) == GL_TIMEOUT_EXPIRED) {
  }
  glDeleteSync(fence);
  fence = nullptr;
}

namespace {
// Set and read from any thread (benchmarks and tests switch and count between extractions).
std::atomic<bool> g_submit_early{true};
std::atomic<int> g_submissions{0};
}  // namespace

void submit() {
  if (!g_submit_early) return;
  glFlush();
  ++g_submissions;
}

void set_submit_early(bool on) {
  g_submit_early = on;
}

int submissions() {
  return g_submissions;
}

void dispatch(std::uint64_t n) {
  if (n == 0) return;
  const std::uint64_t groups = (n + 255) / 256;
  const std::uint64_t x = std::min<std::uint64_t>(groups, 65535);
  const std::uint64_t y = (groups + x - 1) / x;
  glDispatchCompute(static_cast<GLuint>(x), static_cast<GLuint>(y), 1);
  // Every pass reads what the one before wrote through storage buffers.
  glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
}

namespace {

// The std140 layout of `Tables` in mc_common.glsl, filled from a case table with MC's fields.
template <class Table>
std::unique_ptr<Buffer> table_buffer(const Table& ct) {
  struct {
    std::array<std::uint32_t, 256 * 4> tri{};
    std::array<std::uint32_t, 256> mask{};
    std::array<std::int32_t, 12 * 4> edge{};
  } t;
  for (int c = 0; c < 256; ++c) {
    std::uint8_t bytes[16];
    std::memset(bytes, 0xff, sizeof bytes);
    for (int i = 0; i < 3 * mc::kMaxTrianglesPerCase; ++i)
      bytes[i] = static_cast<std::uint8_t>(ct.triangles[c][i]);
    bytes[15] = ct.triangle_count[c];
    std::memcpy(&t.tri[4 * c], bytes, 16);  // little-endian, as GL's uint is on the host
    t.mask[c] = ct.edge_mask[c];
  }
  for (int e = 0; e < 12; ++e) {
    const int lo = mc::kEdgeCorners[e][0];
    t.edge[4 * e + 0] = lo & 1;
    t.edge[4 * e + 1] = (lo >> 1) & 1;
    t.edge[4 * e + 2] = (lo >> 2) & 1;
    t.edge[4 * e + 3] = e / 4;
  }
  return std::make_unique<Buffer>(sizeof t, &t);
}

}  // namespace

void bind_case_tables(CaseTable which) {
  std::unique_ptr<Buffer>& tables = case_tables(which);
  if (!tables) at_shutdown(release_programs);
  if (!tables)
    tables = which == CaseTable::Macet ? table_buffer(detail::macet_case_table(true))
                                       : table_buffer(mc::kCaseTable);
  tables->bind(GL_UNIFORM_BUFFER, 0);
}

void set_grid_uniforms(GLuint prog, const GridUniforms& u) {
  auto i3 = [&](const char* name, const Index3& v) {
    glProgramUniform3i(prog, glGetUniformLocation(prog, name), static_cast<GLint>(v[0]),
                       static_cast<GLint>(v[1]), static_cast<GLint>(v[2]));
  };
  auto d3 = [&](const char* name, const Vec3d& v) {
    glProgramUniform3d(prog, glGetUniformLocation(prog, name), v[0], v[1], v[2]);
  };
  i3("u_region_lo", u.region.lo);
  i3("u_region_dims", {u.region.extent(0), u.region.extent(1), u.region.extent(2)});
  i3("u_global_dims", u.global_dims);
  i3("u_box_lo", u.cells.lo);
  i3("u_box_hi", u.cells.hi);
  glProgramUniform1d(prog, glGetUniformLocation(prog, "u_iso"), u.iso);
  // As core/extract/inside_bits.h: iso rounded up to a float, so that v >= it <=> double(v) >= iso.
  float iso_float = static_cast<float>(u.iso);
  if (static_cast<double>(iso_float) < u.iso)
    iso_float = std::nextafter(iso_float, std::numeric_limits<float>::infinity());
  glProgramUniform1f(prog, glGetUniformLocation(prog, "u_iso_float"), iso_float);
  glProgramUniform1f(prog, glGetUniformLocation(prog, "u_iso_nearest"), static_cast<float>(u.iso));
  d3("u_origin", u.origin);
  d3("u_spacing", u.spacing);
  check("setting the grid uniforms");
}

}  // namespace isotile::gl
