// The HistoPyramid's count pyramid in three layouts, and a second output design, side by side in
// one run on the same volumes (docs/gl.md, "HistoPyramid layout: measured"):
//   linear  the production layout (shaders/mc_histopyramid.cpp): elements in (z, y, x) order, a
//           node sums eight consecutive nodes of the level below;
//   block   storage buffers in 2x2x2 blocks per level ("Morton per level"): node p of level l at
//           8 * lin(p / 2) + octant(p), so a node's children are consecutive and its 3D
//           neighbours close; levels padded to even dims only (a full Morton order would pad the
//           brick to a power-of-two cube);
//   texture one 3D integer texture per level (R16UI codes, RG32UI counts; GL mipmaps halve with
//           floor, a chain would need the brick padded to powers of two), imageStore / texelFetch.
//   compact the linear-8 pyramid with the other output design: no descent; a down-sweep gives
//           every level-1 node its vertices and triangles before it, then one invocation per
//           element writes its own outputs (a stream compaction).
// Timed per layout: "build" = classification + every reduction level (what the issue calls the
// pyramid construction; compact: its down-sweep too), then "descend" = one invocation per vertex
// and one per triangle descending to its element (the traversal of the output passes, without
// computing positions; compact: "scatter", one invocation per element writing its outputs).
// Every layout must give the CPU's vertex and triangle counts, and its descents the same multiset
// of elements (sum of element indices per kind); the linear descent must also come out in element
// order, and the compact scatter give the same arrays. "hp" is the production path's whole
// extraction, for scale.
// A second table times the production build (classification, reduction, the vertex offsets'
// down-sweep, the totals) with 1, 2 and 3 pyramid levels per dispatch (hp_pyramid.h), after
// checking that all three give the same pyramid and offsets, word for word.
//
//   cmake --build build-gl --target bench_hp_layouts -j2
//   build-gl/tests/benchmarks/bench_hp_layouts [--threads N] [--repeat R] [--data DIR]
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "core/extract/marching_cubes.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "shaders/gl_program.h"
#include "shaders/hp_pyramid.h"
#include "shaders/sample_upload.h"

namespace {

using namespace isotile;
using namespace isotile::gl;

constexpr int kMaxLevels = 16;

struct Case {
  std::string name;
  std::shared_ptr<Volume> volume;
  double iso;
};

[[noreturn]] void fail(const std::string& what) {
  std::fflush(stdout);  // the rows so far first, then the failure
  std::fprintf(stderr, "FAILED: %s\n", what.c_str());
  std::exit(2);
}

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void set_u(GLuint prog, const char* name, std::uint32_t v) {
  glProgramUniform1ui(prog, glGetUniformLocation(prog, name), v);
}
void set_i(GLuint prog, const char* name, int v) {
  glProgramUniform1i(prog, glGetUniformLocation(prog, name), v);
}
void set_u3v(GLuint prog, const char* name, const std::vector<std::array<std::uint32_t, 3>>& v) {
  glProgramUniform3uiv(prog, glGetUniformLocation(prog, name), static_cast<GLsizei>(v.size()),
                       v.front().data());
}
void set_uv(GLuint prog, const char* name, const std::vector<std::uint32_t>& v) {
  glProgramUniform1uiv(prog, glGetUniformLocation(prog, name), static_cast<GLsizei>(v.size()),
                       v.data());
}

using Dims = std::array<std::uint32_t, 3>;
std::uint64_t volume_of(const Dims& d) {
  return std::uint64_t{d[0]} * d[1] * d[2];
}

std::string with_base(const std::string& defines) {
  std::string s = defines;  // appended, not concatenated: GCC 12's -Wrestrict
  s += "#define BASE\n";
  return s;
}

// What one layout produced: totals and, per kind, the element of every output.
struct Result {
  std::uint32_t totals[2] = {};
  std::vector<std::uint32_t> elements[2];
};

struct Timing {
  double build = 0, descend = 0;
};

// Shared per volume: the uploaded samples and the grid uniforms.
struct Setup {
  Samples samples;
  GridUniforms grid;
  Dims d{};  // elements along x, y, z (samples of the closed cell box)
};

// The descents of one layout: dispatches `prog` for both kinds into `out`, reads back.
void descend(GLuint prog, const std::uint32_t totals[2], Result& r, Timing& t) {
  glFinish();
  const double t0 = now();
  // Rounded up so that the second range starts at a storage-buffer offset alignment (<= 256 B).
  const std::uint32_t most = (std::max(totals[0], totals[1]) + 63) / 64 * 64;
  const Buffer out(std::uint64_t{most} * 4 * 2);
  for (int which = 0; which < 2; ++which) {
    glBindBufferRange(GL_SHADER_STORAGE_BUFFER, 3, out.id(),
                      static_cast<GLintptr>(which) * most * 4,
                      static_cast<GLsizeiptr>(std::max<std::uint32_t>(most, 1) * 4));
    set_u(prog, "u_count", totals[which]);
    set_i(prog, "u_which", which);
    glUseProgram(prog);
    dispatch(totals[which]);
  }
  glFinish();
  check("descending a pyramid");
  t.descend = now() - t0;
  for (int which = 0; which < 2; ++which) {
    r.elements[which].resize(totals[which]);
    out.read(static_cast<std::size_t>(which) * most * 4, std::size_t{totals[which]} * 4,
             r.elements[which].data());
  }
}

// The production layout's count pyramid (linear-8, shaders/hp_pyramid.h's levels): nodes summing
// eight consecutive nodes of the level below, all in one buffer. Shared by the linear and the
// compact runs.
struct LinearPyramid {
  Pyramid shape;
  Buffer codes, pyr;
  explicit LinearPyramid(std::uint64_t elements) : shape(elements) {}
};

// Classification and every reduction level into `p` (codes at binding 1, pyramid at 2),
// `per_pass` levels per dispatch as in production (hp_pyramid.h; 0: the device's default); the
// totals read back into `r`.
void build_linear(const Setup& s, LinearPyramid& p, Result& r, int per_pass = 0) {
  const std::string& defines = s.samples.defines;
  const GLuint classify = program({{GL_COMPUTE_SHADER, "hp_classify.comp"}}, defines);
  set_grid_uniforms(classify, s.grid);
  const std::uint64_t elements = p.shape.count[0];
  p.codes = Buffer(((elements + 1) / 2) * 4);
  p.pyr = Buffer(p.shape.nodes * 8);
  p.codes.bind(GL_SHADER_STORAGE_BUFFER, 1);
  p.pyr.bind(GL_SHADER_STORAGE_BUFFER, 2);
  glUseProgram(classify);
  dispatch((elements + 1) / 2);
  reduce_levels(p.shape, defines, per_pass);
  check("building the linear pyramid");
  p.pyr.read(std::size_t{p.shape.offset[p.shape.levels]} * 8, 8, r.totals);
}

// The production build (classification, reduction, the vertex offsets' down-sweep, the totals)
// with `per_pass` levels per dispatch, timed; `bytes` gets the pyramid's and the offsets' bytes.
double time_build(const Setup& s, int per_pass, std::vector<std::uint32_t>& bytes) {
  LinearPyramid p(volume_of(s.d));
  glFinish();
  const double t0 = now();
  Result r;
  build_linear(s, p, r, per_pass);
  const Buffer offsets(p.shape.nodes * 4);
  offsets.bind(GL_SHADER_STORAGE_BUFFER, 5);
  sweep_offsets(p.shape, s.samples.defines, offsets, per_pass);
  glFinish();
  check("the down-sweep");
  const double t = now() - t0;
  bytes.resize(p.shape.nodes * 3);
  p.pyr.read(0, p.shape.nodes * 8, bytes.data());
  offsets.read(0, p.shape.nodes * 4, bytes.data() + p.shape.nodes * 2);
  return t;
}

Result run_linear(const Setup& s, Timing& t) {
  LinearPyramid p(volume_of(s.d));
  const GLuint find =
      program({{GL_COMPUTE_SHADER, "hp_bench_linear_find.comp"}}, s.samples.defines);
  set_grid_uniforms(find, s.grid);
  glFinish();
  const double t0 = now();
  Result r;
  build_linear(s, p, r);
  t.build = now() - t0;
  p.shape.set_uniforms(find);
  descend(find, r.totals, r, t);
  check("the linear layout");
  return r;
}

// The compact output design on the linear pyramid: the build adds production's down-sweep of
// both kinds' offsets (the per-element output passes', FACE_OFFSETS); then one invocation per
// element writes its outputs' element index (no descent). Timed as build and "descend" like the
// others.
Result run_compact(const Setup& s, Timing& t) {
  LinearPyramid p(volume_of(s.d));
  const std::string& defines = s.samples.defines;
  const GLuint scatter = program({{GL_COMPUTE_SHADER, "hp_bench_compact_scatter.comp"}}, defines);
  set_grid_uniforms(scatter, s.grid);
  p.shape.set_uniforms(scatter);
  glFinish();
  const double t0 = now();
  Result r;
  build_linear(s, p, r);
  const Buffer offsets(p.shape.nodes * 8);
  offsets.bind(GL_SHADER_STORAGE_BUFFER, 5);
  sweep_offsets(p.shape, defines, offsets, 0, true);
  glFinish();
  check("the compact down-sweep");
  t.build = now() - t0;

  const double t1 = now();
  const Buffer vertices(std::max<std::uint64_t>(r.totals[0], 1) * 4);
  const Buffer triangles(std::max<std::uint64_t>(r.totals[1], 1) * 4);
  vertices.bind(GL_SHADER_STORAGE_BUFFER, 3);
  triangles.bind(GL_SHADER_STORAGE_BUFFER, 4);
  glUseProgram(scatter);
  dispatch(p.shape.count[0]);
  glFinish();
  check("the compact scatter");
  t.descend = now() - t1;
  const Buffer* out[2] = {&vertices, &triangles};
  for (int which = 0; which < 2; ++which) {
    r.elements[which].resize(r.totals[which]);
    out[which]->read(0, std::size_t{r.totals[which]} * 4, r.elements[which].data());
  }
  return r;
}

Result run_block(const Setup& s, Timing& t) {
  // Grids per level: level 0 the elements, each the ceiling half of the one below, up to one
  // node (level L); one more all-ones grid above it to address level L's storage.
  std::vector<Dims> dims{s.d};
  while (volume_of(dims.back()) > 1) {
    const Dims& b = dims.back();
    dims.push_back({(b[0] + 1) / 2, (b[1] + 1) / 2, (b[2] + 1) / 2});
  }
  const int levels = static_cast<int>(dims.size()) - 1;
  dims.push_back({1, 1, 1});
  if (levels < 1 || levels >= kMaxLevels) fail("block layout: unexpected level count");
  std::vector<std::uint32_t> boff(17, 0), stored(17, 0);
  std::uint64_t nodes = 0;
  for (int l = 0; l <= levels; ++l) {
    stored[l] = static_cast<std::uint32_t>(8 * volume_of(dims[l + 1]));
    if (l >= 1) {
      boff[l] = static_cast<std::uint32_t>(nodes);
      nodes += stored[l];
    }
  }
  std::vector<Dims> udims(dims);
  udims.resize(17, Dims{1, 1, 1});

  const std::string& defines = s.samples.defines;
  const GLuint classify = program({{GL_COMPUTE_SHADER, "hp_bench_block_classify.comp"}}, defines);
  const GLuint base =
      program({{GL_COMPUTE_SHADER, "hp_bench_block_reduce.comp"}}, with_base(defines));
  const GLuint upper = program({{GL_COMPUTE_SHADER, "hp_bench_block_reduce.comp"}}, defines);
  const GLuint find = program({{GL_COMPUTE_SHADER, "hp_bench_block_find.comp"}}, defines);
  for (GLuint p : {classify, base, upper, find}) {
    set_grid_uniforms(p, s.grid);
    set_u3v(p, "u_bdims", udims);
  }
  for (GLuint p : {base, upper, find}) set_uv(p, "u_boff", boff);

  glFinish();
  const double t0 = now();
  const std::uint32_t words = stored[0] / 2;
  const Buffer codes(std::uint64_t{words} * 4);
  const Buffer pyr(nodes * 8);
  codes.bind(GL_SHADER_STORAGE_BUFFER, 6);
  pyr.bind(GL_SHADER_STORAGE_BUFFER, 7);
  set_u(classify, "u_words", words);
  glUseProgram(classify);
  dispatch(words);
  for (int l = 1; l <= levels; ++l) {
    const GLuint prog = l == 1 ? base : upper;
    set_i(prog, "u_blevel", l);
    set_u(prog, "u_stored", stored[l]);
    glUseProgram(prog);
    dispatch(stored[l]);
  }
  check("building the block pyramid");
  Result r;
  pyr.read(std::size_t{boff[levels]} * 8, 8, r.totals);
  t.build = now() - t0;

  set_i(find, "u_blevels", levels);
  descend(find, r.totals, r, t);
  check("the block layout");
  return r;
}

// A 3D integer texture of one level, NEAREST so that it is complete.
struct Texture {
  GLuint id = 0;
  explicit Texture(GLenum format, const Dims& d) {
    glCreateTextures(GL_TEXTURE_3D, 1, &id);
    glTextureParameteri(id, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(id, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTextureStorage3D(id, 1, format, static_cast<GLsizei>(d[0]), static_cast<GLsizei>(d[1]),
                       static_cast<GLsizei>(d[2]));
  }
  ~Texture() { glDeleteTextures(1, &id); }
  Texture(const Texture&) = delete;
  Texture& operator=(const Texture&) = delete;
};

void dispatch_images(std::uint64_t n) {
  dispatch(n);
  glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT | GL_TEXTURE_FETCH_BARRIER_BIT);
}

Result run_texture(const Setup& s, Timing& t) {
  std::vector<Dims> dims{s.d};
  while (volume_of(dims.back()) > 1) {
    const Dims& b = dims.back();
    dims.push_back({(b[0] + 1) / 2, (b[1] + 1) / 2, (b[2] + 1) / 2});
  }
  const int levels = static_cast<int>(dims.size()) - 1;
  if (levels < 1 || levels >= kMaxLevels) fail("texture layout: unexpected level count");
  std::vector<Dims> udims(dims);
  udims.resize(16, Dims{1, 1, 1});

  const std::string& defines = s.samples.defines;
  const GLuint classify = program({{GL_COMPUTE_SHADER, "hp_bench_tex_classify.comp"}}, defines);
  const GLuint base =
      program({{GL_COMPUTE_SHADER, "hp_bench_tex_reduce.comp"}}, with_base(defines));
  const GLuint upper = program({{GL_COMPUTE_SHADER, "hp_bench_tex_reduce.comp"}}, defines);
  const GLuint find = program({{GL_COMPUTE_SHADER, "hp_bench_tex_find.comp"}}, defines);
  for (GLuint p : {classify, base, upper, find}) set_grid_uniforms(p, s.grid);

  glFinish();
  const double t0 = now();
  std::vector<std::unique_ptr<Texture>> tex;
  tex.push_back(std::make_unique<Texture>(GL_R16UI, dims[0]));
  for (int l = 1; l <= levels; ++l) tex.push_back(std::make_unique<Texture>(GL_RG32UI, dims[l]));
  glProgramUniform3ui(classify, glGetUniformLocation(classify, "u_tdim0"), dims[0][0], dims[0][1],
                      dims[0][2]);
  glBindImageTexture(0, tex[0]->id, 0, GL_TRUE, 0, GL_WRITE_ONLY, GL_R16UI);
  glUseProgram(classify);
  dispatch_images(volume_of(dims[0]));
  for (int l = 1; l <= levels; ++l) {
    const GLuint prog = l == 1 ? base : upper;
    glProgramUniform3ui(prog, glGetUniformLocation(prog, "u_src_dims"), dims[l - 1][0],
                        dims[l - 1][1], dims[l - 1][2]);
    glProgramUniform3ui(prog, glGetUniformLocation(prog, "u_dst_dims"), dims[l][0], dims[l][1],
                        dims[l][2]);
    glBindTextureUnit(0, tex[l - 1]->id);
    glBindImageTexture(1, tex[l]->id, 0, GL_TRUE, 0, GL_WRITE_ONLY, GL_RG32UI);
    glUseProgram(prog);
    dispatch_images(volume_of(dims[l]));
  }
  Result r;
  glGetTextureImage(tex[levels]->id, 0, GL_RG_INTEGER, GL_UNSIGNED_INT, 8, r.totals);
  t.build = now() - t0;

  for (int l = 0; l <= levels; ++l) glBindTextureUnit(static_cast<GLuint>(l), tex[l]->id);
  set_u3v(find, "u_tdims", udims);
  set_i(find, "u_tlevels", levels);
  descend(find, r.totals, r, t);
  for (int l = 0; l <= levels; ++l) glBindTextureUnit(static_cast<GLuint>(l), 0);
  check("the texture layout");
  return r;
}

std::uint64_t sum_of(const std::vector<std::uint32_t>& v) {
  return std::accumulate(v.begin(), v.end(), std::uint64_t{0});
}

}  // namespace

int main(int argc, char** argv) {
  // Each row as it is measured, also into a pipe (tee): a run cut short keeps what it printed.
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  int threads = 2, repeat = 5;
  // engine from --data DIR, else $ISOTILE_GPU_DATA (a GPU machine does not see ../shared), else
  // ../shared/data.
  std::filesystem::path data = ISOTILE_SHARED_DATA;
  if (const char* env = std::getenv("ISOTILE_GPU_DATA"); env && *env) data = env;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) threads = std::atoi(argv[++i]);
    if (std::strcmp(argv[i], "--repeat") == 0 && i + 1 < argc) repeat = std::atoi(argv[++i]);
    if (std::strcmp(argv[i], "--data") == 0 && i + 1 < argc) data = argv[++i];
  }
  repeat = std::max(repeat, 1);
  setenv("LP_NUM_THREADS", std::to_string(threads).c_str(), 1);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  std::string why;
  if (!available(&why)) {
    std::printf("no GL context: %s\n", why.c_str());
    return 1;
  }
  const DeviceInfo& dev = device();
  std::printf("device: %s (%s, %s), threads %d, median of %d runs\n", dev.renderer.c_str(),
              dev.platform.c_str(), dev.version.c_str(), threads, repeat);

  std::vector<Case> cases;
  for (auto [kind, n] : {std::pair{FieldKind::Sphere, 128}, std::pair{FieldKind::Gyroid, 256}}) {
    const FieldSpec spec{kind, n};
    cases.push_back({std::string(field_name(kind)) + "-" + std::to_string(n),
                     std::make_shared<Volume>(make_field_volume(spec)), field_default_iso(kind)});
  }
  const auto engine = data / "engine_256x256x128_uint8.raw.gz";
  if (std::filesystem::exists(engine))
    cases.push_back({"engine", std::make_shared<Volume>(read_volume(engine.string())), 49.5});
  else
    std::printf("skipping engine: %s not found\n", engine.c_str());

  std::printf("%-11s %9s %9s | %21s | %21s | %21s | %21s | %8s\n", "", "", "",
              "linear-8 (production)", "2x2x2 blocks", "3D textures", "compact (linear-8)", "");
  std::printf("%-11s %9s %9s | %10s %10s | %10s %10s | %10s %10s | %10s %10s | %8s\n", "volume",
              "vertices", "triangles", "build ms", "descend", "build ms", "descend", "build ms",
              "descend", "build ms", "scatter", "hp ms");
  std::vector<std::string> pass_rows;  // the second table, printed after the first
  for (const Case& c : cases) {
    const VolumeView v = c.volume->view();
    const Mesh cpu = marching_cubes(v, {.iso = c.iso});
    Scope scope;
    bind_case_tables();
    const Box3 cells{{0, 0, 0}, {v.dims[0] - 1, v.dims[1] - 1, v.dims[2] - 1}};
    const Box3 region{{0, 0, 0}, v.dims};
    Setup s{upload_samples(v, region),
            GridUniforms{region, cells, v.global_dims, c.iso, v.origin, v.spacing},
            {static_cast<std::uint32_t>(v.dims[0]), static_cast<std::uint32_t>(v.dims[1]),
             static_cast<std::uint32_t>(v.dims[2])}};
    s.samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);

    using Runner = Result (*)(const Setup&, Timing&);
    constexpr int kRunners = 4;
    const Runner runners[kRunners] = {run_linear, run_block, run_texture, run_compact};
    std::vector<double> build[kRunners], desc[kRunners], hp;
    Result ref[kRunners];
    for (int i = 0; i < kRunners; ++i) {  // once untimed: compiles the shaders, gives the results
      Timing t;
      ref[i] = runners[i](s, t);
    }
    for (int r = 0; r < repeat; ++r) {
      for (int i = 0; i < kRunners; ++i) {  // interleaved: load changes hit every layout alike
        Timing t;
        runners[i](s, t);
        build[i].push_back(t.build);
        desc[i].push_back(t.descend);
      }
      s.samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);
      const double t0 = now();
      mc_histopyramid(v, {.iso = c.iso});
      hp.push_back(now() - t0);
      s.samples.buffer.bind(GL_SHADER_STORAGE_BUFFER, 0);  // mc_histopyramid rebinds 0
      bind_case_tables();
    }

    // Same counts as the CPU, the same elements from every descent, element order for linear,
    // and the compact scatter's arrays equal to the linear descent's, output by output.
    for (int i = 0; i < kRunners; ++i) {
      if (ref[i].totals[0] != cpu.positions.size() || ref[i].totals[1] != cpu.triangles.size())
        fail(c.name + ": layout " + std::to_string(i) + " counts " +
             std::to_string(ref[i].totals[0]) + " / " + std::to_string(ref[i].totals[1]) +
             ", the CPU " + std::to_string(cpu.positions.size()) + " / " +
             std::to_string(cpu.triangles.size()));
      for (int which = 0; which < 2; ++which)
        if (sum_of(ref[i].elements[which]) != sum_of(ref[0].elements[which]))
          fail(c.name + ": layout " + std::to_string(i) + " descends to other elements");
    }
    for (int which = 0; which < 2; ++which) {
      if (!std::is_sorted(ref[0].elements[which].begin(), ref[0].elements[which].end()))
        fail(c.name + ": the linear descent is not in element order");
      if (ref[3].elements[which] != ref[0].elements[which])
        fail(c.name + ": the compact scatter puts outputs elsewhere than the linear descent");
    }

    auto med = [](std::vector<double> t) {
      std::sort(t.begin(), t.end());
      return 1e3 * t[t.size() / 2];
    };
    // The production build with 1, 2 and 3 levels per dispatch: the same pyramid and offsets,
    // and how long each takes.
    {
      std::vector<std::uint32_t> first, bytes;
      std::vector<double> times[kMaxLevelsPerPass];
      for (int k = 1; k <= kMaxLevelsPerPass; ++k) {
        time_build(s, k, bytes);  // untimed: compiles, and gives the words to compare
        if (k == 1) first = bytes;
        if (bytes != first)
          fail(c.name + ": " + std::to_string(k) +
               " levels per pass build another pyramid or other offsets than one");
      }
      for (int r = 0; r < repeat; ++r)
        for (int k = 1; k <= kMaxLevelsPerPass; ++k)
          times[k - 1].push_back(time_build(s, k, bytes));
      const Pyramid shape(volume_of(s.d));
      char row[160];
      std::snprintf(row, sizeof row, "%-11s %6d | %10.1f %10.1f %10.1f | %8d %8d %8d\n",
                    c.name.c_str(), shape.levels, med(times[0]), med(times[1]), med(times[2]),
                    2 * shape.levels - 1, (shape.levels + 1) / 2 + shape.levels / 2,
                    (shape.levels + 2) / 3 + (shape.levels + 1) / 3);
      pass_rows.push_back(row);
    }
    std::printf(
        "%-11s %9zu %9zu | %10.1f %10.1f | %10.1f %10.1f | %10.1f %10.1f | %10.1f %10.1f | %8.1f\n",
        c.name.c_str(), cpu.positions.size(), cpu.triangles.size(), med(build[0]), med(desc[0]),
        med(build[1]), med(desc[1]), med(build[2]), med(desc[2]), med(build[3]), med(desc[3]),
        med(hp));
    std::fflush(stdout);
  }
  // Dispatches: the reduction ceil(L / k), the down-sweep of levels L-1..1 ceil((L - 1) / k).
  std::printf("\nproduction build (classify, reduce, down-sweep, totals) by levels per pass, ms\n");
  std::printf("%-11s %6s | %10s %10s %10s | %26s\n", "volume", "levels", "1 per pass", "2 per pass",
              "3 per pass", "reduce + sweep passes");
  for (const std::string& row : pass_rows) std::fputs(row.c_str(), stdout);
  return 0;
}
