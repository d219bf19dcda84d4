#include "macet_gl.h"

#include <bit>
#include <cstdio>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/inside_bits.h"
#include "core/extract/isovalue_ties.h"
#include "core/extract/macet_field.h"
#include "core/extract/macet_relax.h"
#include "core/extract/macet_search.h"
#include "core/extract/macet_table.h"
#include "gl_context.h"
#include "gl_program.h"
#include "sample_upload.h"

namespace isotile::gl {

// Core's constants by their bits (glsl_double()), not as decimal literals for the driver to parse.
std::string macet_defines() {
  auto d = [](const char* name, double v) {
    return "#define " + std::string(name) + " " + glsl_double(v) + "\n";
  };
  std::string s = "#define MACET\n";
  s += d("MACET_REACH", detail::kMacetReach);
  s += d("MACET_PUSH_CAP", detail::kMacetPushCap);
  s += d("MACET_SMOOTH_CAP", detail::kMacetSmoothCap);
  s += d("MACET_GUARD", detail::kMacetGuard);
  s += d("MACET_SMOOTH_GUARD", detail::kMacetSmoothGuard);
  s += d("MACET_TIE_OFFSET", detail::kTieOffset);
  s += d("MACET_ROOT_TOLERANCE", detail::kRootTolerance);
  s += d("MACET_ROOT_WIDTH", detail::kRootWidth);
  s += "#define MACET_HALVINGS " + std::to_string(detail::kMacetHalvings) + "\n";
  return s;
}

namespace {

// Bytes per region sample of one displacement buffer: dvec4 (displacement, f - iso).
constexpr std::size_t kDispBytes = 32;

// Max's local search on the CPU over the slab's region (the CPU's view for this slab), from the
// displacements the device computed; returns them updated, laid out as on the device.
template <class T>
void local_search(const VolumeView& region, const MacetOptions& o, std::vector<double>& disp) {
  using namespace detail;
  const Field<T> field(region, o.iso);
  BitGrid grid;
  grid.nx = region.dims[0];
  grid.ny = region.dims[1];
  grid.nz = region.dims[2];
  grid.words = (grid.nx + 63) / 64;
  grid.bits.resize(static_cast<std::size_t>(grid.ny * grid.nz * grid.words));
  classify<T>(region, o.iso, grid);
  auto inside = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return (grid.row(j, k)[i >> 6] >> (i & 63)) & 1;
  };
  // The grid vertices (samples with a neighbour on the other side), ranked x fastest.
  GridVertices gv;
  gv.box = Box3{{0, 0, 0}, region.dims};
  gv.words = grid.words;
  gv.ny = grid.ny;
  const std::int64_t rows = grid.ny * grid.nz;
  gv.bits.assign(static_cast<std::size_t>(rows * grid.words), 0);
  gv.prefix.assign(static_cast<std::size_t>(rows * grid.words), 0);
  std::vector<std::int64_t> samples;  // region index of each grid vertex
  for (std::int64_t r = 0; r < rows; ++r) {
    const std::int64_t j = r % grid.ny, k = r / grid.ny;
    for (std::int64_t i = 0; i < grid.nx; ++i) {
      if ((i & 63) == 0)
        gv.prefix[static_cast<std::size_t>(r * grid.words + (i >> 6))] =
            static_cast<std::uint32_t>(samples.size());
      const std::int64_t p[3] = {i, j, k};
      const bool in = inside(i, j, k);
      bool touched = false;
      for (int a = 0; a < 3 && !touched; ++a)
        for (int dir = -1; dir <= 1 && !touched; dir += 2) {
          std::int64_t q[3] = {p[0], p[1], p[2]};
          q[a] += dir;
          touched = q[a] >= 0 && q[a] < region.dims[a] && inside(q[0], q[1], q[2]) != in;
        }
      if (!touched) continue;
      gv.bits[static_cast<std::size_t>(r * grid.words + (i >> 6))] |= std::uint64_t{1} << (i & 63);
      samples.push_back(i + grid.nx * r);
    }
  }
  gv.disp.resize(samples.size());
  gv.value.resize(samples.size());
  for (std::size_t n = 0; n < samples.size(); ++n) {
    const double* d = disp.data() + 4 * samples[n];
    gv.disp[n] = {d[0], d[1], d[2]};
    gv.value[n] = d[3];
  }
  macet_local_search(field, grid, gv, macet_case_table(true), o.max_sweeps);
  for (std::size_t n = 0; n < samples.size(); ++n) {
    double* d = disp.data() + 4 * samples[n];
    for (int c = 0; c < 3; ++c) d[c] = gv.disp[n][c];
    d[3] = gv.value[n];
  }
}

EdgeMethod macet_method(const VolumeView& view, const MacetOptions& o) {
  EdgeMethod m;
  m.halo = macet_halo(o);
  // Two displacement buffers and, during the smoothing, the linear crossings (three per sample).
  m.bytes_per_sample = 5 * kDispBytes;
  m.largest_per_sample = 3 * kDispBytes;
  m.defines = macet_defines();
  m.table = CaseTable::Macet;
  m.prepare = [view, o](const Samples&, const GridUniforms& grid, const std::string& defines) {
    const Box3& r = grid.region;
    const std::uint64_t n = static_cast<std::uint64_t>(r.extent(0) * r.extent(1) * r.extent(2));
    std::vector<Buffer> disp;
    disp.emplace_back(n * kDispBytes);
    disp.emplace_back(n * kDispBytes);
    // The push writes buffer 1; the smoothing reads it and writes buffer 0, which the vertex
    // passes read.
    disp[1].bind(GL_SHADER_STORAGE_BUFFER, 7);
    GLuint prog = program({{GL_COMPUTE_SHADER, "macet_push.comp"}}, defines);
    set_grid_uniforms(prog, grid);
    glUseProgram(prog);
    dispatch(n);
    disp[1].bind(GL_SHADER_STORAGE_BUFFER, 6);
    {
      // The crossings' linear estimates, read by the smoothing only.
      const Buffer linear(3 * n * kDispBytes);
      linear.bind(GL_SHADER_STORAGE_BUFFER, 8);
      prog = program({{GL_COMPUTE_SHADER, "macet_linear.comp"}}, defines);
      set_grid_uniforms(prog, grid);
      glUseProgram(prog);
      dispatch(n);
      disp[0].bind(GL_SHADER_STORAGE_BUFFER, 7);
      prog = program({{GL_COMPUTE_SHADER, "macet_smooth.comp"}}, defines);
      set_grid_uniforms(prog, grid);
      glUseProgram(prog);
      dispatch(n);
    }
    check("displacing Macet's grid vertices");
    if (o.quality == MacetQuality::Max) {
      std::vector<double> host(4 * n);
      disp[0].read(0, n * kDispBytes, host.data());
      Box3 local;
      for (int a = 0; a < 3; ++a) {
        local.lo[a] = r.lo[a] - view.box.lo[a];
        local.hi[a] = r.hi[a] - view.box.lo[a];
      }
      const VolumeView sub = subview(view, local);
      visit_scalar(sub.type, [&](auto tag) { local_search<decltype(tag)>(sub, o, host); });
      disp[0] = Buffer(n * kDispBytes, host.data());
    }
    disp[0].bind(GL_SHADER_STORAGE_BUFFER, 6);
    return disp;
  };
  return m;
}

// Runs `path` on `view`, or on its relaxed samples (the CPU's pre-pass) when relax is asked for.
template <class Path>
Mesh run(const VolumeView& view, const MacetGlOptions& options, McStats* stats, Path path) {
  const MacetOptions& o = options.macet;
  check_macet_options(o);
  McOptions mc;
  mc.iso = o.iso;
  mc.normals = o.normals;
  mc.cells = o.cells;
  mc.memory = options.memory;
  mc.max_brick_cells_z = options.max_brick_cells_z;
  mc.capture_bytes = options.capture_bytes;
  mc.progress = o.progress;
  if (o.relax > 0) {
    // As macet(): the relaxed samples are doubles, uploaded as such.
    const detail::ScratchVector<double> samples =
        detail::relax_pinned_samples(view, o.iso, o.relax);
    VolumeView relaxed = view;
    relaxed.data = samples.data();
    relaxed.type = ScalarType::Float64;
    relaxed.strides = {1, view.dims[0], view.dims[0] * view.dims[1]};
    return path(relaxed, mc, stats, macet_method(relaxed, o));
  }
  return path(view, mc, stats, macet_method(view, o));
}

}  // namespace

Mesh macet_histopyramid(const VolumeView& view, const MacetGlOptions& options, McStats* stats) {
  return run(view, options, stats, histopyramid_mesh);
}

Mesh macet_geometry_shader(const VolumeView& view, const MacetGlOptions& options, McStats* stats) {
  return run(view, options, stats, geometry_shader_mesh);
}

}  // namespace isotile::gl
