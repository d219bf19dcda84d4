// The OpenGL Marching Cubes backends (geometry shader, HistoPyramid) against the CPU reference:
// the same mesh (vertices in key order, triangles cell by cell), whole-volume, sliced into slabs,
// in brick mode, with a capture buffer that overflows, and for every sample width. Runs on any
// OpenGL 4.5 device; on CPU-only machines on Mesa's llvmpipe. Skips when no context can be made.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/extract/marching_cubes.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "gl_test_support.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "shaders/gl_program.h"
#include "shaders/hp_pyramid.h"
#include "shaders/read_back.h"
#include "shaders/sample_upload.h"
#include "test_support.h"
#include "tiler/tiled_extract.h"
#include "tiler/volume_source.h"

namespace isotile {
namespace {

using testing::shared_volume;

using Path = testing::GlPath;

Mesh run(Path p, const VolumeView& v, const gl::McOptions& o, gl::McStats* stats = nullptr) {
  return p == Path::Gs ? gl::mc_geometry_shader(v, o, stats) : gl::mc_histopyramid(v, o, stats);
}

// The CPU's mesh bit for bit (gl_test_support.h).
void expect_same_mesh(const Mesh& gl, const Mesh& cpu, const VolumeView& v, const char* what) {
  testing::expect_same_gl_mesh(gl, cpu, v, what);
}

// A field sampled into a volume of another scalar type, scaled so that integers keep the shape.
Volume convert(const Volume& src, ScalarType type, double scale, double offset) {
  Volume out(type, src.dims(), src.spacing(), src.origin());
  const float* in = src.data<float>();
  visit_scalar(type, [&](auto tag) {
    using T = decltype(tag);
    T* dst = out.data<T>();
    for (std::int64_t i = 0; i < src.sample_count(); ++i)
      dst[i] = static_cast<T>(std::round(in[i] * scale + offset));
  });
  return out;
}

class GlPaths : public ::testing::TestWithParam<Path> {};

TEST_P(GlPaths, FieldsEqualCpu) {
  REQUIRE_GL();
  for (const char* name : {"field:sphere:33", "field:gyroid:48", "field:torus:37"})
    for (bool normals : {false, true}) {
      const FieldSpec spec = *parse_field_spec(name);
      Volume vol = make_field_volume(spec);
      vol.set_spacing({0.5, 1.0, 2.0});
      vol.set_origin({-3.0, 0.25, 7.0});
      const double iso = field_default_iso(spec.kind);
      const Mesh cpu = marching_cubes(vol.view(), {.iso = iso, .normals = normals});
      ASSERT_GT(cpu.triangles.size(), 100u);
      const Mesh gl = run(GetParam(), vol.view(), {.iso = iso, .normals = normals});
      expect_same_mesh(gl, cpu, vol.view(), (std::string(name) + (normals ? " +n" : "")).c_str());
    }
}

// Every sample width: 8/16-bit integers and float upload as float, 32-bit integers and doubles
// as double; the inside test must agree with the CPU's at values equal to the isovalue.
TEST_P(GlPaths, EveryScalarTypeEqualsCpu) {
  REQUIRE_GL();
  const Volume field = make_field_volume({FieldKind::Gyroid, 29});
  for (ScalarType t : {ScalarType::Int8, ScalarType::UInt8, ScalarType::Int16, ScalarType::UInt16,
                       ScalarType::Int32, ScalarType::UInt32, ScalarType::Float64}) {
    const bool is_unsigned =
        t == ScalarType::UInt8 || t == ScalarType::UInt16 || t == ScalarType::UInt32;
    const Volume v = convert(field, t, 40.0, is_unsigned ? 64.0 : 0.0);
    const double iso = is_unsigned ? 64.0 : 0.0;  // many samples exactly at the isovalue
    const Mesh cpu = marching_cubes(v.view(), {.iso = iso, .normals = true});
    const Mesh gl = run(GetParam(), v.view(), {.iso = iso, .normals = true});
    expect_same_mesh(gl, cpu, v.view(), std::string(scalar_name(t)).c_str());
  }
}

// Each type over its whole range (sign extension of packed 8- and 16-bit samples, 32-bit integers
// beyond a float's exact range, doubles closer together than floats), from views whose rows start
// in the middle of a 32-bit word (odd x extents and offsets), whole and as bricks.
TEST_P(GlPaths, FullRangeOfEveryTypeEqualsCpu) {
  REQUIRE_GL();
  const Volume field = make_field_volume({FieldKind::Gyroid, 23});
  const float* f = field.data<float>();
  const auto [lo_it, hi_it] = std::minmax_element(f, f + field.sample_count());
  for (ScalarType t :
       {ScalarType::Int8, ScalarType::UInt8, ScalarType::Int16, ScalarType::UInt16,
        ScalarType::Int32, ScalarType::UInt32, ScalarType::Float32, ScalarType::Float64}) {
    Volume v(t, field.dims(), field.spacing(), field.origin());
    double iso = 0;
    visit_scalar(t, [&](auto tag) {
      using T = decltype(tag);
      const double lo = t == ScalarType::Float64   ? 0.1
                        : t == ScalarType::Float32 ? -3e38
                                                   : double(std::numeric_limits<T>::lowest());
      const double hi = t == ScalarType::Float64   ? 0.1 + 1e-12
                        : t == ScalarType::Float32 ? 3e38
                                                   : double(std::numeric_limits<T>::max());
      for (std::int64_t i = 0; i < field.sample_count(); ++i) {
        const double u = (f[i] - *lo_it) / double(*hi_it - *lo_it);
        v.data<T>()[i] = static_cast<T>(std::is_integral_v<T> ? std::round(lo + u * (hi - lo))
                                                              : lo + u * (hi - lo));
      }
      // The isovalue is one of the samples: ties at it everywhere along its level.
      iso = double(v.data<T>()[field.sample_count() / 2 + 5]);
    });
    const std::string what(scalar_name(t));
    const Mesh cpu = marching_cubes(v.view(), {.iso = iso, .normals = true});
    ASSERT_GT(cpu.triangles.size(), 100u) << what;
    expect_same_mesh(run(GetParam(), v.view(), {.iso = iso, .normals = true}), cpu, v.view(),
                     what.c_str());
    const Box3 cells{{3, 5, 1}, {16, 20, 12}};
    const Box3 local{{1, 3, 0}, {19, 23, 15}};  // cells plus the halo of 2 and one
    const VolumeView view = subview(v.view(), local);
    const Mesh cpu_brick = marching_cubes(view, {.iso = iso, .normals = true, .cells = cells});
    const Mesh gl_brick = run(
        GetParam(), view, {.iso = iso, .normals = true, .cells = cells, .max_brick_cells_z = 4});
    expect_same_mesh(gl_brick, cpu_brick, view, (what + " brick").c_str());
  }
}

// The slabs of the staging tests below: gyroid 29^3 as int16 in slabs of 5 cells, through staging
// buffers of three 29 x 29 planes and a bit (set_staging_bytes(kSmallStaging)). Each slab's region
// has its cells' planes plus one more and the normals' halo of one each side, clipped to the
// volume: the planes of each slab's region, in order.
constexpr std::size_t kSmallStaging = 29 * 29 * 2 * 3 + 6;
Volume small_slab_volume() {
  return convert(make_field_volume({FieldKind::Gyroid, 29}), ScalarType::Int16, 40.0, 0.0);
}
std::vector<std::int64_t> small_slab_planes() {
  std::vector<std::int64_t> planes;
  for (std::int64_t z = 0; z < 28; z += 5) {
    const std::int64_t hi = std::min<std::int64_t>(z + 5, 28);
    planes.push_back(std::min<std::int64_t>(hi + 3, 29) - std::max<std::int64_t>(z - 1, 0));
  }
  return planes;
}

// The staging buffers (pinned, persistently mapped) are made once and reused by every slab and
// run: with buffers far smaller than a slab, each slab's samples pass through all of them in turn,
// and the mesh is unchanged. The stats count exactly the samples of the slabs' regions, each
// uploaded once (the early uploads are used, not repeated).
TEST_P(GlPaths, StagingBuffersAreReusedAcrossSlabsAndRuns) {
  REQUIRE_GL();
  const Volume v = small_slab_volume();
  const Mesh cpu = marching_cubes(v.view(), {.iso = 0.0, .normals = true});
  gl::Scope scope;
  gl::set_staging_bytes(kSmallStaging);
  const int before = gl::staging_buffers_created();
  for (int r = 0; r < 3; ++r) {
    gl::McStats stats;
    const Mesh gl =
        run(GetParam(), v.view(), {.iso = 0.0, .normals = true, .max_brick_cells_z = 5}, &stats);
    expect_same_mesh(gl, cpu, v.view(), "small staging buffers");
    EXPECT_EQ(stats.bricks, 6);
    // Both paths upload every slab but the first while the one before is counted (HistoPyramid)
    // or drawn (geometry shader).
    EXPECT_EQ(stats.early_uploads, 5);
    std::uint64_t planes = 0;
    for (const std::int64_t p : small_slab_planes()) planes += static_cast<std::uint64_t>(p);
    EXPECT_EQ(stats.times.upload_bytes, planes * 29 * 29 * 2);
    EXPECT_GT(stats.times[gl::GlStage::Upload], 0.0);
  }
  EXPECT_EQ(gl::staging_buffers_created() - before, gl::kStagingBuffers);
  gl::set_staging_bytes(gl::kDefaultStagingBytes);
}

// The commands are handed to the device (gl::submit(): glFlush) wherever the CPU goes on to work
// of its own: after each chunk of an upload (the CPU fills the next staging buffer), before the
// next slab's early upload (its rows are copied while the device counts or draws this slab), and,
// on the HistoPyramid path, before the CPU sizes the mesh's arrays behind the output passes. Off,
// the commands wait for the next wait, as before; the mesh is the same either way.
TEST_P(GlPaths, CommandsAreSubmittedBeforeTheCpuWorksAlone) {
  REQUIRE_GL();
  const Volume v = small_slab_volume();
  const Mesh cpu = marching_cubes(v.view(), {.iso = 0.0, .normals = true});
  gl::Scope scope;
  gl::set_staging_bytes(kSmallStaging);
  // A chunk per 3 planes of each slab's region.
  const std::vector<std::int64_t> planes = small_slab_planes();
  const int slabs = static_cast<int>(planes.size());
  int chunks = 0;
  for (const std::int64_t p : planes) chunks += static_cast<int>((p + 2) / 3);
  const int per_path = GetParam() == Path::Hp ? 2 * slabs - 1 : slabs - 1;
  for (const bool early : {true, false}) {
    gl::set_submit_early(early);
    const int before = gl::submissions();
    gl::McStats stats;
    const Mesh gl =
        run(GetParam(), v.view(), {.iso = 0.0, .normals = true, .max_brick_cells_z = 5}, &stats);
    gl::set_submit_early(true);
    expect_same_mesh(gl, cpu, v.view(), early ? "submitted early" : "not submitted early");
    ASSERT_EQ(stats.bricks, slabs);
    EXPECT_EQ(gl::submissions() - before, early ? chunks + per_path : 0);
  }
  gl::set_staging_bytes(gl::kDefaultStagingBytes);
}

// The mesh's arrays come back through the pinned read-back buffers (read_back.h): with pieces far
// smaller than the arrays (an odd size, so pieces end inside a vertex), every piece passes through
// the few buffers in turn, the buffers are made once for all slabs and runs, and the mesh is the
// CPU's. The same with every read straight through glGetNamedBufferSubData, and with the device's
// own choice.
TEST_P(GlPaths, MeshReadBackThroughPinnedBuffers) {
  REQUIRE_GL();
  const Volume v = make_field_volume({FieldKind::Gyroid, 48});
  const double iso = field_default_iso(FieldKind::Gyroid);
  const Mesh cpu = marching_cubes(v.view(), {.iso = iso, .normals = true});
  // The slabs' arrays must be large enough for the pinned path (kPinnedReadMinBytes).
  ASSERT_GT(cpu.triangles.size() * sizeof(Tri) / 2, gl::kPinnedReadMinBytes);
  gl::Scope scope;
  for (const std::size_t piece : {std::size_t{10'007}, std::size_t{0}}) {
    gl::set_read_back_bytes(piece);
    const int before = gl::read_back_buffers_created();
    for (int r = 0; r < 2; ++r) {
      gl::McStats stats;
      const Mesh gl =
          run(GetParam(), v.view(), {.iso = iso, .normals = true, .max_brick_cells_z = 24}, &stats);
      EXPECT_EQ(stats.bricks, 2);
      expect_same_mesh(gl, cpu, v.view(), piece ? "pinned pieces" : "direct reads");
    }
    EXPECT_EQ(gl::read_back_buffers_created() - before, piece ? gl::kReadBackBuffers : 0);
  }
  // By default a software rasteriser reads straight through GL, a hardware device through the
  // pinned buffers: as many as its largest read has pieces of kDefaultReadBackBytes, up to
  // kReadBackBuffers (this mesh's arrays are smaller than one piece).
  gl::use_default_read_back();
  const int before = gl::read_back_buffers_created();
  expect_same_mesh(run(GetParam(), v.view(), {.iso = iso, .normals = true}), cpu, v.view(),
                   "the device's choice");
  ASSERT_LT(cpu.triangles.size() * sizeof(Tri), gl::kDefaultReadBackBytes);
  EXPECT_EQ(gl::read_back_buffers_created() - before, gl::device().software ? 0 : 1);
}

// The pinned buffers of the upload and of the read-back are no larger than the transfers need
// (the driver pins, and llvmpipe zeroes, every byte when one is made): 1 MiB for a small volume
// and mesh, where they were 32 and 8 MiB whatever the volume; a larger transfer makes them again,
// larger, and a smaller one after it keeps them.
TEST(GlTransfers, PinnedBuffersAreNoLargerThanTheTransfersNeed) {
  REQUIRE_GL();
  gl::Scope scope;
  gl::set_staging_bytes(gl::kDefaultStagingBytes);     // none held: from nothing
  gl::set_read_back_bytes(gl::kDefaultReadBackBytes);  // through pinned buffers on any device
  constexpr std::size_t kMiB = std::size_t{1} << 20;
  auto largest_array = [](const Mesh& m) {
    return std::max(m.positions.size() * sizeof(Vec3f), m.triangles.size() * sizeof(Tri));
  };
  const double iso = field_default_iso(FieldKind::Gyroid);
  const Volume small = make_field_volume({FieldKind::Gyroid, 48});  // 432 KiB of samples
  const Mesh small_cpu = marching_cubes(small.view(), {.iso = iso});
  ASSERT_GT(largest_array(small_cpu), gl::kPinnedReadMinBytes);
  ASSERT_LT(largest_array(small_cpu), kMiB);
  expect_same_mesh(gl::mc_histopyramid(small.view(), {.iso = iso}), small_cpu, small.view(),
                   "small");
  EXPECT_EQ(gl::staging_bytes_held(), kMiB);
  EXPECT_EQ(gl::read_back_bytes_held(), kMiB);
  const Volume large = make_field_volume({FieldKind::Gyroid, 128});  // 8 MiB of samples
  const Mesh large_cpu = marching_cubes(large.view(), {.iso = iso});
  expect_same_mesh(gl::mc_histopyramid(large.view(), {.iso = iso}), large_cpu, large.view(),
                   "large");
  EXPECT_EQ(gl::staging_bytes_held(), 8 * kMiB);
  EXPECT_EQ(gl::read_back_bytes_held(), std::bit_ceil(largest_array(large_cpu)));
  const int staging_made = gl::staging_buffers_created();
  const int read_back_made = gl::read_back_buffers_created();
  expect_same_mesh(gl::mc_histopyramid(small.view(), {.iso = iso}), small_cpu, small.view(),
                   "small again");
  EXPECT_EQ(gl::staging_buffers_created(), staging_made);
  EXPECT_EQ(gl::read_back_buffers_created(), read_back_made);
  gl::set_staging_bytes(gl::kDefaultStagingBytes);
  gl::use_default_read_back();
}

// read_back() itself, on bytes it can check: any offset and length, pieces of any size, a read
// smaller than kPinnedReadMinBytes straight through GL.
TEST(GlReadBack, GivesTheBuffersBytes) {
  REQUIRE_GL();
  gl::Scope scope;
  std::vector<unsigned char> pattern(1'000'003);
  for (std::size_t i = 0; i < pattern.size(); ++i)
    pattern[i] = static_cast<unsigned char>((i * 2654435761u) >> 13);
  const gl::Buffer buffer(pattern.size(), pattern.data());
  struct Read {
    std::size_t offset, bytes;
  };
  for (const std::size_t piece : {gl::kDefaultReadBackBytes, std::size_t{65'537}, std::size_t{0}}) {
    gl::set_read_back_bytes(piece);
    for (const Read r : {Read{0, pattern.size()}, Read{12'345, 700'001}, Read{999'000, 1'003},
                         Read{3, gl::kPinnedReadMinBytes}}) {
      std::vector<unsigned char> out(r.bytes, 0xAB);
      buffer.read(r.offset, r.bytes, out.data());
      EXPECT_TRUE(std::equal(out.begin(), out.end(), pattern.begin() + r.offset))
          << "piece " << piece << ", offset " << r.offset << ", " << r.bytes << " bytes";
    }
  }
  gl::use_default_read_back();
}

// Slabs along z (as for a volume larger than the device's memory) give the whole-volume mesh.
TEST_P(GlPaths, SlabsEqualWholeVolume) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Torus, 41});
  const double iso = field_default_iso(FieldKind::Torus);
  const Mesh cpu = marching_cubes(vol.view(), {.iso = iso, .normals = true});
  for (std::int64_t slab : {1, 2, 7, 13}) {
    gl::McStats stats;
    const Mesh gl = run(GetParam(), vol.view(),
                        {.iso = iso, .normals = true, .max_brick_cells_z = slab}, &stats);
    EXPECT_EQ(stats.bricks, (40 + slab - 1) / slab);
    expect_same_mesh(gl, cpu, vol.view(), ("slab " + std::to_string(slab)).c_str());
  }
}

// Progress (core/progress.h): Stage::Extract once per slab after its begin; a cancel stops the
// extraction between slabs with Cancelled, and the context still works afterwards.
TEST_P(GlPaths, ReportsPerSlabAndStopsWhenCancelled) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Torus, 41});
  const double iso = field_default_iso(FieldKind::Torus);
  int calls = 0;
  Progress progress([&](const ProgressUpdate& u) {
    EXPECT_EQ(u.stage, Stage::Extract);
    ++calls;
    return true;
  });
  gl::McStats stats;
  const Mesh whole = run(GetParam(), vol.view(),
                         {.iso = iso, .max_brick_cells_z = 4, .progress = &progress}, &stats);
  EXPECT_EQ(calls, 1 + stats.bricks);
  int seen = 0;
  Progress stop([&](const ProgressUpdate&) { return ++seen < 3; });
  EXPECT_THROW(run(GetParam(), vol.view(), {.iso = iso, .max_brick_cells_z = 4, .progress = &stop}),
               Cancelled);
  EXPECT_EQ(seen, 3);
  EXPECT_EQ(run(GetParam(), vol.view(), {.iso = iso, .max_brick_cells_z = 4}).triangles,
            whole.triangles);
}

// Brick mode (the tiler's contract, core/extract/marching_cubes.h): the GL output for a box of
// cells from a view holding it plus the halo equals the CPU's brick output.
TEST_P(GlPaths, BrickModeEqualsCpu) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 40});
  const VolumeView whole = vol.view();
  for (bool normals : {false, true}) {
    const int halo = marching_cubes_halo({.normals = normals});
    for (const Box3& cells : {Box3{{0, 0, 0}, {1, 1, 1}}, Box3{{5, 3, 11}, {18, 20, 17}},
                              Box3{{30, 0, 29}, {39, 39, 39}}, Box3{{0, 33, 2}, {7, 39, 9}}}) {
      Box3 local;
      for (int a = 0; a < 3; ++a) {
        local.lo[a] = std::max<std::int64_t>(cells.lo[a] - halo, 0);
        local.hi[a] = std::min<std::int64_t>(cells.hi[a] + halo + 1, whole.dims[a]);
      }
      const VolumeView view = subview(whole, local);
      const Mesh cpu = marching_cubes(view, {.iso = 0.0, .normals = normals, .cells = cells});
      for (std::int64_t slab : {0, 2}) {
        const Mesh gl =
            run(GetParam(), view, {.normals = normals, .cells = cells, .max_brick_cells_z = slab});
        expect_same_mesh(gl, cpu, view, "brick");
      }
    }
  }
}

TEST_P(GlPaths, RealVolumeEqualsCpu) {
  REQUIRE_GL();
  const auto path = shared_volume("neghip_66x66x66_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(path);
  const Volume vol = read_volume(path.string());
  for (double iso : {25.5, 100.0}) {
    const Mesh cpu = marching_cubes(vol.view(), {.iso = iso, .normals = true});
    ASSERT_GT(cpu.triangles.size(), 1000u);
    const Mesh gl = run(GetParam(), vol.view(), {.iso = iso, .normals = true});
    expect_same_mesh(gl, cpu, vol.view(), "neghip");
  }
}

TEST_P(GlPaths, EmptyAndTinyVolumes) {
  REQUIRE_GL();
  // No crossing at all, and the smallest volume with a cell.
  const Volume vol = make_field_volume({FieldKind::Sphere, 16});
  EXPECT_TRUE(run(GetParam(), vol.view(), {.iso = 1e9}).triangles.empty());
  EXPECT_TRUE(run(GetParam(), vol.view(), {.iso = 1e9}).positions.empty());
  float s[8] = {1, 0, 0, 0, 0, 0, 0, 0};
  const VolumeView tiny = dense_view(s, ScalarType::Float32, {2, 2, 2});
  const Mesh cpu = marching_cubes(tiny, {.iso = 0.5});
  ASSERT_EQ(cpu.triangles.size(), 1u);
  expect_same_mesh(run(GetParam(), tiny, {.iso = 0.5}), cpu, tiny, "one cell");
}

INSTANTIATE_TEST_SUITE_P(Gl, GlPaths, ::testing::Values(Path::Gs, Path::Hp),
                         [](const auto& info) { return info.param == Path::Gs ? "Gs" : "Hp"; });

// A capture buffer far too small: the geometry-shader path detects the overflow (written <
// generated), drops the cut cell and resumes; the result is unchanged.
TEST(GlGeometryShader, CaptureOverflowResumes) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 24});
  const Mesh cpu = marching_cubes(vol.view(), {.iso = 0.0, .normals = true});
  for (std::uint64_t bytes : {1u, 500u, 20000u}) {
    gl::McStats stats;
    const Mesh gl = gl::mc_geometry_shader(
        vol.view(), {.normals = true, .max_brick_cells_z = 9, .capture_bytes = bytes}, &stats);
    EXPECT_GT(stats.capture_passes, stats.bricks) << bytes;
    expect_same_mesh(gl, cpu, vol.view(), "overflow");
  }
}

// HistoPyramid output passes larger than their buffers (half the memory budget) run chunk by
// chunk, each read back before the next; those that fit run both passes before the mesh's
// arrays are sized. Random samples make a dense surface (several triangles per cell), so small
// budgets need several chunks per slab; every budget gives the CPU's mesh.
TEST(GlHistoPyramid, ChunkedOutputPassesEqualCpu) {
  REQUIRE_GL();
  Volume vol(ScalarType::UInt8, {37, 29, 23}, {1, 1, 1}, {0, 0, 0});
  std::uint32_t state = 12345;
  for (std::int64_t i = 0; i < vol.sample_count(); ++i) {
    state = state * 1664525u + 1013904223u;
    vol.data<std::uint8_t>()[i] = static_cast<std::uint8_t>(state >> 24);
  }
  const Mesh cpu = marching_cubes(vol.view(), {.iso = 127.5, .normals = true});
  ASSERT_GT(cpu.triangles.size(), 20000u);
  for (const std::uint64_t memory :
       {std::uint64_t{96} << 10, std::uint64_t{400} << 10, std::uint64_t{0}}) {
    gl::McStats stats;
    const Mesh gl =
        gl::mc_histopyramid(vol.view(), {.iso = 127.5, .normals = true, .memory = memory}, &stats);
    expect_same_mesh(gl, cpu, vol.view(), ("memory " + std::to_string(memory)).c_str());
    // One vertex and one face dispatch per slab where they fit, more where they do not.
    if (memory) {
      EXPECT_GT(stats.output_chunks, 2 * stats.bricks) << memory;
    } else {
      EXPECT_EQ(stats.output_chunks, 2 * stats.bricks);
      // One slab of 37 x 29 x 23 elements: five pyramid levels, built and swept in 5 + 4
      // passes at one level per pass, 2 + 2 at three (hp_pyramid.h).
      ASSERT_EQ(stats.bricks, 1);
      EXPECT_EQ(gl::Pyramid(vol.sample_count()).levels, 5);
      EXPECT_EQ(stats.pyramid_passes, gl::default_levels_per_pass() == 1 ? 9 : 4);
    }
  }
}

// The count pyramid and its vertex offsets (hp_pyramid.h) from random element codes, against
// sums made here: every level and every offset, word for word, for 1, 2 and 3 levels per
// dispatch, with element counts that end inside a workgroup's 256 nodes and pyramids of 1 to 7
// levels (one level per pass is a software device's default, without the shaders' shared memory
// and barriers). DC_CODES counts need no case table: vertices in bits 11-13, one face per bit
// 8-10.
TEST(GlHistoPyramid, PyramidLevelsAndOffsetsEqualSumsOnTheCpu) {
  REQUIRE_GL();
  gl::Scope scope;
  std::string defines = gl::sample_defines(ScalarType::Float32);
  defines += "#define DC_CODES\n";
  std::uint32_t state = 987654321u;
  for (const std::uint64_t elements : {1u, 8u, 9u, 511u, 513u, 4097u, 33'000u, 300'001u}) {
    // One more code than elements, which the passes must not count (an odd count's last word).
    std::vector<std::uint16_t> codes(elements + 1, 0x3f00);
    for (std::uint64_t e = 0; e < elements; ++e) {
      state = state * 1664525u + 1013904223u;
      // Mostly empty elements, as in a volume; a few with up to 7 vertices and 3 faces.
      codes[e] = (state >> 28) < 3 ? static_cast<std::uint16_t>(state & 0x3f00u) : 0;
    }
    const gl::Pyramid pyr(elements);
    // Expected: (vertices, faces) per node, level by level; the vertices' offsets top-down, then
    // the faces' (the per-element output passes' down-sweep, FACE_OFFSETS).
    std::vector<std::uint32_t> want(pyr.nodes * 4, 0);
    auto node = [&](int l, std::uint64_t p) { return &want[2 * (pyr.offset[l] + p)]; };
    for (int l = 1; l <= pyr.levels; ++l)
      for (std::uint64_t q = 0; q < pyr.count[l - 1]; ++q) {
        std::uint32_t* dst = node(l, q / 8);
        if (l == 1) {
          dst[0] += (codes[q] >> 11) & 7u;
          dst[1] += static_cast<std::uint32_t>(std::popcount(codes[q] >> 8 & 7u));
        } else {
          dst[0] += node(l - 1, q)[0];
          dst[1] += node(l - 1, q)[1];
        }
      }
    for (int kind = 0; kind < 2; ++kind) {
      std::uint32_t* offset = want.data() + pyr.nodes * (2 + kind);
      for (int l = pyr.levels - 1; l >= 1; --l)
        for (std::uint64_t p = 0; p < pyr.count[l]; ++p) {
          std::uint32_t sum = offset[pyr.offset[l + 1] + p / 8];
          for (std::uint64_t q = p & ~std::uint64_t{7}; q < p; ++q) sum += node(l, q)[kind];
          offset[pyr.offset[l] + p] = sum;
        }
    }
    ASSERT_GT(node(pyr.levels, 0)[0], 0u) << elements;  // some vertices at all
    for (int per_pass = 1; per_pass <= gl::kMaxLevelsPerPass; ++per_pass)
      for (const bool faces : {false, true}) {
        const gl::Buffer code_buffer(codes.size() * 2, codes.data());
        const gl::Buffer levels(pyr.nodes * 8), offsets(pyr.nodes * 4 * (faces ? 2 : 1));
        code_buffer.bind(GL_SHADER_STORAGE_BUFFER, 1);
        levels.bind(GL_SHADER_STORAGE_BUFFER, 2);
        offsets.bind(GL_SHADER_STORAGE_BUFFER, 5);
        const int reduce_passes = gl::reduce_levels(pyr, defines, per_pass);
        const int sweep_passes = gl::sweep_offsets(pyr, defines, offsets, per_pass, faces);
        EXPECT_EQ(reduce_passes, (pyr.levels + per_pass - 1) / per_pass);
        EXPECT_EQ(sweep_passes, (pyr.levels - 1 + per_pass - 1) / per_pass);
        // The pyramid, the vertices' offsets and, with `faces`, the faces'.
        const std::size_t words = pyr.nodes * (faces ? 4 : 3);
        std::vector<std::uint32_t> got(words, 0xdeadbeefu);
        levels.read(0, pyr.nodes * 8, got.data());
        offsets.read(0, (words - pyr.nodes * 2) * 4, got.data() + pyr.nodes * 2);
        EXPECT_EQ(got, std::vector<std::uint32_t>(want.begin(), want.begin() + words))
            << elements << " elements, " << per_pass << " levels per pass, face offsets " << faces;
      }
  }
  EXPECT_THROW(gl::reduce_levels(gl::Pyramid(8), defines, 4), Error);
}

// A program the driver rejects is one error line naming its file, with the driver's log joined
// (Mesa's has a line per error and ends with a newline), as every message of the library is; under
// auto it becomes the warning's one line.
TEST(GlProgram, ARejectedProgramIsOneLine) {
  REQUIRE_GL();
  gl::Scope scope;
  try {
    gl::program({{GL_COMPUTE_SHADER, "hp_classify.comp"}}, "not glsl;\nnor this;\n");
    ADD_FAILURE() << "the driver took it";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("compiling hp_classify.comp failed: ", 0), 0u) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_FALSE(std::isspace(static_cast<unsigned char>(m.back()))) << m;
  }
}

TEST(GlBackends, RegisteredInTheTable) {
  REQUIRE_GL();
  gl::register_gl_backends();
  const Volume vol = make_field_volume({FieldKind::Sphere, 20});
  const Mesh cpu = marching_cubes(vol.view(), {.iso = 0.0});
  for (Backend b : {Backend::GeometryShader, Backend::HistoPyramid}) {
    const ExtractOptions o{.backend = b};
    EXPECT_EQ(resolve_backend(o), b);
    expect_same_mesh(extract(vol.view(), o), cpu, vol.view(), "table");
  }
  // Auto takes a GPU path only on a real GPU.
  const Backend a = resolve_backend({});
  // Never a GL path on a software device; on a GPU whatever the rules say (the CPU everywhere
  // until a GL path is measured faster: kAutoRules).
  if (gl::device().software) {
    EXPECT_EQ(a, Backend::Cpu);
  }
  for (const BackendCaps& c : capabilities())
    if (c.backend != Backend::Cpu) {
      EXPECT_TRUE(c.available);
      EXPECT_EQ(c.hardware, !gl::device().software);
    }
}

// Taking the context after a thread's outermost Scope gave it back cost about 0.2 s a time on
// the H200 (docs/gl.md): the context stays current on its own thread, where the extractions run,
// so that once it is made an extraction through core's table, with the report the CLI and the
// tiler ask for, takes it no more, nor does asking for the device's description (the backends'
// probe does, once per extraction).
TEST(GlBackends, AnExtractionTakesNothingOnceTheContextIsMade) {
  REQUIRE_GL();
  gl::register_gl_backends();
  const Volume vol = make_field_volume({FieldKind::Sphere, 20});
  gl::device();
  const int before = gl::context_takes();
  gl::device();
  EXPECT_EQ(gl::context_takes() - before, 0) << "device()";
  for (Backend b : {Backend::GeometryShader, Backend::HistoPyramid})
    for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring}) {
      const ExtractOptions o{.method = m, .backend = b};
      BackendChoice ran;
      const Mesh mesh = extract(vol.view(), o, &ran);
      EXPECT_EQ(gl::context_takes() - before, 0) << method_name(m) << " on " << int(b);
      EXPECT_TRUE(ran.gpu.has_value());
      EXPECT_FALSE(mesh.triangles.empty());
    }
}

// prepare_backend(), called while the caller reads its volume: the method's programs for the
// sample type, and the staging buffers for the volume's bytes, are made on the context's thread
// then, so that the extraction that follows makes none; its report counts them as its own.
TEST(GlBackends, PreparedWhileTheVolumeIsRead) {
  REQUIRE_GL();
  gl::register_gl_backends();
  gl::device();
  gl::set_staging_bytes(gl::kDefaultStagingBytes);  // none held
  const Volume field = make_field_volume({FieldKind::Gyroid, 30});
  auto keys = [] { return gl::on_context_thread([] { return gl::built_program_keys(); }); };
  // A sample type per backend and method, so that each starts with none of its programs built.
  const ScalarType types[] = {ScalarType::Int8,   ScalarType::UInt8, ScalarType::Int16,
                              ScalarType::UInt16, ScalarType::Int32, ScalarType::UInt32};
  int next = 0;
  for (Backend b : {Backend::GeometryShader, Backend::HistoPyramid})
    for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring}) {
      const ScalarType t = types[next++];
      const bool is_unsigned =
          t == ScalarType::UInt8 || t == ScalarType::UInt16 || t == ScalarType::UInt32;
      const Volume vol = convert(field, t, 40.0, is_unsigned ? 64.0 : 0.0);
      ExtractOptions o;
      o.method = m;
      o.backend = b;
      o.iso = is_unsigned ? 64.5 : 0.5;
      const std::string what = std::string(method_name(m)) + " on " + std::string(backend_name(b)) +
                               ", " + std::string(scalar_name(t));
      const std::vector<std::string> before = keys();
      // The first also makes the staging buffer of a 3 MiB volume: one of 4 MiB.
      prepare_backend(o, t, next == 1 ? 3u << 20 : vol.byte_size());
      const std::vector<std::string> prepared = keys();
      EXPECT_GT(prepared.size(), before.size()) << what;
      if (next == 1) {
        EXPECT_EQ(gl::staging_bytes_held(), std::size_t{4} << 20);
      }
      BackendChoice ran;
      const Mesh mesh = extract(vol.view(), o, &ran);
      EXPECT_FALSE(mesh.triangles.empty()) << what;
      EXPECT_EQ(keys(), prepared) << what << ": the extraction built programs of its own";
      ASSERT_TRUE(ran.gpu.has_value()) << what;
      EXPECT_EQ(ran.gpu->programs_loaded + ran.gpu->programs_compiled,
                static_cast<int>(prepared.size() - before.size()))
          << what;
      if (next == 1) {
        double pinned = 0;
        for (const auto& [name, seconds] : ran.gpu->seconds)
          if (name == "pinned") pinned = seconds;
        EXPECT_GT(pinned, 0.0) << what << ": the staging buffer made for it";
      }
    }
  // Two preparations before one extraction: its report counts what both made.
  ExtractOptions o;
  o.backend = Backend::HistoPyramid;
  o.iso = 0.5;
  const std::vector<std::string> before = keys();
  prepare_backend(o, ScalarType::Float64, 64 * 8);
  const std::size_t first = keys().size() - before.size();
  EXPECT_GT(first, 0u);
  prepare_backend(o, ScalarType::Float32, 64 * 4);
  BackendChoice ran;
  extract(field.view(), o, &ran);
  ASSERT_TRUE(ran.gpu.has_value());
  EXPECT_EQ(ran.gpu->programs_loaded + ran.gpu->programs_compiled,
            static_cast<int>(keys().size() - before.size()));
  gl::set_staging_bytes(gl::kDefaultStagingBytes);
}

// A tiled run extracts its bricks on whichever threads the pipeline runs them, each through the
// context's thread: none takes the context, simplified or not, and the file is the CPU's.
class GlTiled : public testing::TempDirTest {
 protected:
  GlTiled() : TempDirTest("isotile-gl-tiled-") {}
};

TEST_F(GlTiled, ARunTakesNothingForItsBricks) {
  REQUIRE_GL();
  gl::register_gl_backends();
  gl::device();
  for (const double simplify : {1.0, 0.5}) {
    TiledOptions to;
    to.extract.iso = 0;
    to.extract.method = Method::Macet;
    to.memory = std::uint64_t{512} << 10;
    to.simplify = simplify;
    std::string files[2];
    std::int64_t bricks = 0;
    for (const Backend b : {Backend::Cpu, Backend::HistoPyramid}) {
      to.extract.backend = b;
      const auto out = dir_ / (std::string(backend_name(b)) + ".ply");
      const int before = gl::context_takes();
      const TiledResult r = extract_tiled(*open_volume_source("field:gyroid:40", {}), to, out);
      bricks = r.plan.total();
      EXPECT_EQ(gl::context_takes() - before, 0)
          << "simplify " << simplify << ", " << bricks << " bricks";
      files[b == Backend::Cpu ? 0 : 1] = slurp(out);
    }
    EXPECT_GT(bricks, 3) << "simplify " << simplify;
    EXPECT_TRUE(files[0] == files[1]) << "simplify " << simplify;
  }
}

// The context's thread: jobs run there, one result or exception back each, in the caller's thread
// limit; a Scope inside a job takes nothing. A Scope on another thread borrows the context (one
// take), jobs asked for inside it run in place, and the next job after it takes the context back
// there (one more).
TEST(GlContextThread, RunsJobsWhereTheContextStays) {
  REQUIRE_GL();
  gl::device();
  const std::thread::id here = std::this_thread::get_id();
  const std::thread::id there = gl::on_context_thread([] { return std::this_thread::get_id(); });
  EXPECT_NE(there, here);
  int before = gl::context_takes();
  for (int i = 0; i < 3; ++i) gl::on_context_thread([] { gl::Scope scope; });
  EXPECT_EQ(gl::context_takes() - before, 0);
  EXPECT_THROW(gl::on_context_thread([]() -> int { throw Cancelled(); }), Cancelled);
  EXPECT_EQ(gl::on_context_thread([] { return 7; }), 7);  // still serving after a job threw
  EXPECT_EQ(gl::on_context_thread([] { return std::this_thread::get_id(); }), there);
  // There it would wait for itself.
  EXPECT_THROW(gl::on_context_thread([] { gl::shutdown(); }), Error);
  EXPECT_TRUE(gl::context_alive());
  tbb::task_arena one(1);
  EXPECT_EQ(one.execute([] {
    return gl::on_context_thread([] { return tbb::this_task_arena::max_concurrency(); });
  }),
            1);
  before = gl::context_takes();
  {
    gl::Scope borrowed;
    EXPECT_EQ(gl::context_takes() - before, 1);
    EXPECT_EQ(gl::on_context_thread([] { return std::this_thread::get_id(); }), here);
    EXPECT_EQ(gl::context_takes() - before, 1);
  }
  const Volume vol = make_field_volume({FieldKind::Sphere, 16});
  const Mesh cpu = marching_cubes(vol.view(), {.iso = 0.0});
  expect_same_mesh(gl::mc_histopyramid(vol.view(), {.iso = 0.0}), cpu, vol.view(), "taken back");
  EXPECT_EQ(gl::context_takes() - before, 2);
}

// Extractions asked for from several threads at once run one at a time on the context's thread,
// each with the CPU's mesh, while another thread borrows the context now and then.
TEST(GlContextThread, ServesSeveralThreadsAtOnce) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 20});
  const Mesh cpu = marching_cubes(vol.view(), {.iso = 0.0});
  std::atomic<int> same{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t)
    threads.emplace_back([&] {
      for (int i = 0; i < 4; ++i) {
        const Mesh m = gl::mc_histopyramid(vol.view(), {.iso = 0.0});
        same += m.positions == cpu.positions && m.triangles == cpu.triangles;
      }
    });
  threads.emplace_back([] {
    for (int i = 0; i < 4; ++i) {
      gl::Scope borrowed;
      glFinish();
    }
  });
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(same.load(), 12);
}

// The context made on a thread of its own (start_context(), what `--backend gs|hp` does while the
// volume is read): the first extraction waits for it and gives the CPU's mesh; starting again
// while it exists does nothing; shutdown() ends it, and a later start makes a new one.
TEST(GlContext, StartedOnAThreadOfItsOwn) {
  REQUIRE_GL();
  const Volume vol = make_field_volume({FieldKind::Gyroid, 24});
  const Mesh cpu = marching_cubes(vol.view(), {.iso = 0.0});
  for (int round = 0; round < 2; ++round) {
    gl::shutdown();
    EXPECT_FALSE(gl::context_alive());
    EXPECT_FALSE(gl::context_started());
    gl::start_context();
    gl::start_context();  // already being made: nothing more
    EXPECT_TRUE(gl::context_started());
    expect_same_mesh(gl::mc_histopyramid(vol.view(), {.iso = 0.0}), cpu, vol.view(), "started");
    EXPECT_TRUE(gl::context_alive());
    gl::start_context();  // exists: nothing
    expect_same_mesh(gl::mc_geometry_shader(vol.view(), {.iso = 0.0}), cpu, vol.view(), "again");
  }
}

TEST(GlContext, DescribesTheDevice) {
  REQUIRE_GL();
  const gl::DeviceInfo& d = gl::device();
  EXPECT_FALSE(d.renderer.empty());
  EXPECT_EQ(d.version.rfind("4.", 0), 0u) << d.version;
  EXPECT_GE(d.max_gs_output_vertices, 15);
  EXPECT_GT(d.max_ssbo_bytes, 0);
  // ISOTILE_GL=device|surfaceless|osmesa forces one way (the GlOsmesa ctest uses it).
  if (const char* way = std::getenv("ISOTILE_GL")) {
    const std::string w = way;
    EXPECT_EQ(d.platform, w == "osmesa" ? w : "egl-" + w);
  }
}

}  // namespace
}  // namespace isotile
