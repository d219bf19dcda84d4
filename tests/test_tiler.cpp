// The out-of-core tiler: the planner keeps to its budget, and a bricked, streamed extraction
// writes exactly the bytes an in-core extraction writes, for every method, budget and input kind.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/mesh/mesh_io.h"
#include "core/progress.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"
#include "tiler/brick_plan.h"
#include "tiler/brick_reader.h"
#include "tiler/tiled_extract.h"
#include "tiler/volume_source.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

class Tiler : public testing::TempDirTest {
 protected:
  Tiler() : TempDirTest("isotile-tiler-") {}

  // In core: read whole, extract, write_mesh. Returns the file's bytes.
  std::string whole(const std::string& input, const ExtractOptions& o, MeshFormat format,
                    const RawOptions& raw = {}) {
    const Volume v = read_volume(input, raw);
    const fs::path out = dir_ / (format == MeshFormat::Ply ? "whole.ply" : "whole.stl");
    write_mesh(extract(v.view(), o), out, {.format = format});
    return slurp(out);
  }

  // Out of core within `memory`. Returns the file's bytes. Runs twice: one brick at a time as
  // small budgets do, and with the next brick read and the last written while one is extracted
  // (as budgets from TiledOptions::overlap_min_memory on do); both must write the same file.
  std::string tiled(const std::string& input, const ExtractOptions& o, MeshFormat format,
                    std::uint64_t memory, TiledResult* result = nullptr,
                    const RawOptions& raw = {}) {
    const fs::path out = dir_ / (format == MeshFormat::Ply ? "tiled.ply" : "tiled.stl");
    TiledOptions to;
    to.extract = o;
    to.memory = memory;
    to.format = format;
    to.overlap_min_memory = ~std::uint64_t{0};
    // Bricks of a few cells stress the seams, however many times over they read the volume.
    to.max_read_amplification = 0;
    const TiledResult r = extract_tiled(*open_volume_source(input, raw), to, out);
    if (result) *result = r;
    const std::string one_at_a_time = slurp(out);
    to.overlap_min_memory = 0;
    const TiledResult overlapped = extract_tiled(*open_volume_source(input, raw), to, out);
    EXPECT_EQ(slurp(out), one_at_a_time) << input << " memory " << memory << " overlapped";
    EXPECT_EQ(overlapped.quality.triangles, r.quality.triangles);
    EXPECT_EQ(overlapped.quality.histogram, r.quality.histogram);
    EXPECT_EQ(overlapped.quality.mean, r.quality.mean);
    return one_at_a_time;
  }
  // `memory` for the bricks plus what the source itself holds (zlib's buffers for gzip), so a
  // small budget cuts a gzip'd volume into as many slabs as a plain one.
  static std::uint64_t plus_buffers(const std::string& input, std::uint64_t memory,
                                    const RawOptions& raw = {}) {
    return memory + open_volume_source(input, raw)->buffer_bytes();
  }
};

ExtractOptions options(Method m, bool normals = false) {
  ExtractOptions o;
  o.method = m;
  o.backend = Backend::Cpu;
  o.normals = normals;
  return o;
}

TEST(BrickPlan, BricksFitTheBudgetAndCoverTheVolumeEvenly) {
  const Index3 dims{301, 77, 1000};
  for (std::uint64_t memory :
       {std::uint64_t{4096}, std::uint64_t{1} << 20, std::uint64_t{1} << 26}) {
    BrickPlanOptions o;
    o.memory = memory;
    o.halo = 2;
    o.sample_bytes = 2;
    const BrickPlan p = plan_bricks(dims, o);
    EXPECT_LE(brick_bytes(p.brick, o), memory);
    for (int a = 0; a < 3; ++a) {
      // Every cell is covered, and no brick is empty.
      EXPECT_GE(p.count[a] * p.brick[a], dims[a] - 1);
      EXPECT_LT((p.count[a] - 1) * p.brick[a], dims[a] - 1);
    }
    // Whole rows with a thick y-z section, or near-cubic: no axis cut much finer than another
    // unless the volume ends first.
    if (p.brick[0] == dims[0] - 1 && p.count[1] * p.count[2] > 1) {
      EXPECT_GE(std::min(p.brick[1], p.brick[2]), std::min<std::int64_t>(64, dims[1] - 1));
    } else {
      const std::int64_t mx = std::max({p.brick[0], p.brick[1], p.brick[2]});
      for (int a = 0; a < 3; ++a)
        if (p.brick[a] < dims[a] - 1) {
          EXPECT_GE(2 * p.brick[a] + 2, mx) << "axis " << a;
        }
    }
    // The last brick's cells end at the volume's last cell.
    EXPECT_EQ(p.cells(p.total() - 1).hi, (Index3{300, 76, 999}));
  }
}

TEST(BrickPlan, SlabsSpanWholeLayersAndTinyBudgetsAreRejected) {
  BrickPlanOptions o;
  o.memory = 16 << 20;
  o.sample_bytes = 1;
  o.slabs = true;
  const BrickPlan p = plan_bricks({512, 512, 64}, o);
  EXPECT_EQ(p.brick[0], 511);
  EXPECT_EQ(p.brick[1], 511);
  EXPECT_EQ(p.count[0] * p.count[1], 1);
  EXPECT_LE(brick_bytes(p.brick, o), o.memory);
  o.memory = 3 << 20;  // less than one cell layer of 512x512 with its halo and output
  EXPECT_THROW(plan_bricks({512, 512, 64}, o), InputError);
  o.slabs = false;
  o.memory = 50;  // less than one cell with its halo
  EXPECT_THROW(plan_bricks({512, 512, 64}, o), InputError);
}

TEST(BrickPlan, ExtractorStateAndClippedHalosCount) {
  // A halo of 51 (Macet max) on a 13 x 11 x 150 volume: clipped to the volume, a slab's view is
  // 13 x 11 samples wide, not 115 x 113.
  BrickPlanOptions o;
  o.halo = 51;
  o.slabs = true;
  o.memory = 200000;
  EXPECT_THROW(plan_bricks({13, 11, 150}, o), InputError);
  o.volume_dims = {13, 11, 150};
  const BrickPlan clipped = plan_bricks({13, 11, 150}, o);
  EXPECT_LE(brick_bytes(clipped.brick, o), o.memory);
  // 4 bytes of state per sample of the view: thinner slabs, and the same budget would be too
  // small for even one layer of a wider volume.
  o.state_bytes_per_sample = 4;
  const BrickPlan with_state = plan_bricks({13, 11, 150}, o);
  EXPECT_LE(brick_bytes(with_state.brick, o), o.memory);
  EXPECT_LT(with_state.brick[2], clipped.brick[2]);
  o.volume_dims = {40, 40, 150};
  EXPECT_THROW(plan_bricks({40, 40, 150}, o), InputError);
}

TEST(BrickPlan, MemorySizesParseWithUnits) {
  EXPECT_EQ(parse_memory_size("256MiB"), 256ull << 20);
  EXPECT_EQ(parse_memory_size("2GB"), 2000000000ull);
  EXPECT_EQ(parse_memory_size("1.5g"), 3ull << 29);
  EXPECT_EQ(parse_memory_size("4096"), 4096ull);
  EXPECT_EQ(parse_memory_size(".5K"), 512ull);
  // Only digits and one point: std::stod took hex, exponents and blanks; below a byte is none.
  for (const char* bad : {"", "MiB", "-5MiB", "0", "12XB", "1e30GB", "nan", "0x1000", "1e3K", " 1M",
                          "1M ", "0.5", ".", "1.2.3M", "+4K", "inf"})
    EXPECT_THROW(parse_memory_size(bad), InputError) << bad;
  // Whole numbers of bytes exactly (through a double, 2^63 - 1 became 2^63); past 1.8e19 bytes,
  // too large, not "expected a positive number".
  EXPECT_EQ(parse_memory_size("9223372036854775807"), 9223372036854775807ull);
  EXPECT_EQ(parse_memory_size("9007199254740993B"), 9007199254740993ull);
  for (const char* huge : {"18446744073709551614", "16777215T", "99999999999999999999TB"}) {
    try {
      parse_memory_size(huge);
      ADD_FAILURE() << huge;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("is more bytes than isotile counts"), std::string::npos)
          << e.what();
    }
  }
}

// Every method and output format, budgets from a few cells per brick to the whole volume.
TEST_F(Tiler, StreamedFileEqualsTheInCoreFile) {
  const std::string field = "field:torus:33";
  for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring})
    for (bool normals : {false, true})
      for (MeshFormat f : {MeshFormat::Ply, MeshFormat::Stl}) {
        const ExtractOptions o = options(m, normals);
        const std::string want = whole(field, o, f);
        ASSERT_GT(want.size(), 10000u);
        for (std::uint64_t memory :
             {std::uint64_t{6000}, std::uint64_t{90000}, std::uint64_t{1} << 30}) {
          TiledResult r;
          EXPECT_EQ(tiled(field, o, f, memory, &r), want)
              << method_name(m) << " normals " << normals << " memory " << memory << " bricks "
              << r.plan.total();
          if (memory == 6000) {
            EXPECT_GT(r.plan.total(), 100);
          }
          if (memory == std::uint64_t{1} << 30) {
            EXPECT_EQ(r.plan.total(), 1);
          }
        }
      }
}

TEST_F(Tiler, QuadsAndParticleSolverStreamExactly) {
  ExtractOptions o = options(Method::DualContouring);
  o.keep_quads = true;
  o.dc_solver = DcSolver::Particle;
  const std::string field = "field:gyroid:37";
  EXPECT_EQ(tiled(field, o, MeshFormat::Ply, 20000), whole(field, o, MeshFormat::Ply));
  EXPECT_EQ(tiled(field, o, MeshFormat::Stl, 20000), whole(field, o, MeshFormat::Stl));
}

// Manifold Dual Contouring's patches depend on the cells across their faces (a face between two
// conflicting cells flips): on noise such faces lie on brick seams, and the streamed file must
// still be the in-core one, raw and gzip'd (slabs), with the cell variant alongside.
TEST_F(Tiler, PatchVerticesStreamExactlyOnNoise) {
  const Index3 n{45, 38, 31};
  std::vector<std::uint8_t> samples(static_cast<std::size_t>(n[0] * n[1] * n[2]));
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> u(0, 3);
  for (std::uint8_t& v : samples) v = static_cast<std::uint8_t>(u(rng));
  const fs::path raw = dir_ / "noise_45x38x31_uint8.raw";
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(samples.data()),
             static_cast<std::streamsize>(samples.size()));
  const fs::path gz = dir_ / "noise_45x38x31_uint8.raw.gz";
  gzFile g = gzopen(gz.c_str(), "wb");
  gzwrite(g, samples.data(), static_cast<unsigned>(samples.size()));
  gzclose(g);
  for (DcVertices vertices : {DcVertices::Patch, DcVertices::Cell}) {
    ExtractOptions o = options(Method::DualContouring, true);
    o.iso = 1.5;
    o.dc_vertices = vertices;
    const std::string want = whole(raw.string(), o, MeshFormat::Ply);
    ASSERT_GT(want.size(), 100000u);
    for (const fs::path& input : {raw, gz})
      for (std::uint64_t memory : {std::uint64_t{60000}, std::uint64_t{300000}}) {
        TiledResult r;
        EXPECT_EQ(
            tiled(input.string(), o, MeshFormat::Ply, plus_buffers(input.string(), memory), &r),
            want)
            << input.filename() << " memory " << memory;
        EXPECT_GT(r.plan.total(), 1u) << input.filename() << " memory " << memory;
      }
  }
}

// DcHermite::Eno streams exactly too; its kink branches only run near sharp features, so csg-box.
// (Its halo of 4 is checked by DualContouring.BricksEqualTheWholeVolume, whose one-cell bricks
// fail with 3; the bricks of these budgets happen not to.)
TEST_F(Tiler, EnoHermiteDataStreamExactlyOnSharpFeatures) {
  ExtractOptions o = options(Method::DualContouring);
  o.dc_solver = DcSolver::Qef;
  o.dc_hermite = DcHermite::Eno;
  const std::string field = "field:csg-box:41";
  const std::string want = whole(field, o, MeshFormat::Ply);
  for (std::uint64_t memory : {std::uint64_t{20000}, std::uint64_t{200000}}) {
    TiledResult r;
    EXPECT_EQ(tiled(field, o, MeshFormat::Ply, memory, &r), want) << "memory " << memory;
    EXPECT_GT(r.plan.total(), 1u) << "memory " << memory;
  }
}

// Marschner-Lobb has radius ratios in the fine bins that straddle the histogram's 0.05 edges
// (2^16 fine bins are not a multiple of 20): summed from them the histogram was off by one or two.
// The mean is the same bits: both sum in RatioSum (in core it was a double sum per chunk, which
// differed in the last bits).
TEST_F(Tiler, StatsMatchTheInCoreMesh) {
  for (const std::string field : {"field:gyroid:40", "field:marschner-lobb:41"}) {
    ExtractOptions o = options(Method::MarchingCubes);
    o.iso = field_default_iso(parse_field_spec(field)->kind);
    const Volume v = read_volume(field);
    const Mesh m = extract(v.view(), o);
    const QualityStats q = triangle_quality(m);
    TiledResult r;
    tiled(field, o, MeshFormat::Ply, 30000, &r);
    EXPECT_EQ(r.vertices, m.positions.size()) << field;
    EXPECT_EQ(r.triangles, m.triangles.size()) << field;
    EXPECT_EQ(r.quality.triangles, q.triangles) << field;
    EXPECT_EQ(r.quality.degenerate, q.degenerate) << field;
    EXPECT_EQ(r.quality.min, q.min) << field;
    EXPECT_EQ(r.quality.mean, q.mean) << field;  // the same integer sum
    EXPECT_NEAR(r.quality.q001, q.q001, 2e-5) << field;
    EXPECT_NEAR(r.quality.q01, q.q01, 2e-5) << field;
    EXPECT_EQ(r.quality.histogram, q.histogram) << field;
  }
}

// Raw files of odd shape in every sample type and byte order, plain and gzip'd (slabs).
TEST_F(Tiler, RawAndGzipInputsStreamExactly) {
  const Index3 dims{37, 23, 41};
  const Volume f = make_field_volume({FieldKind::Gyroid, 41});
  for (ScalarType type : {ScalarType::UInt8, ScalarType::Int16, ScalarType::Float64}) {
    std::vector<char> bytes;
    for (std::int64_t k = 0; k < dims[2]; ++k)
      for (std::int64_t j = 0; j < dims[1]; ++j)
        for (std::int64_t i = 0; i < dims[0]; ++i) {
          const double v = f.view().value(i, j, k);
          visit_scalar(type, [&](auto tag) {
            using T = decltype(tag);
            const T x = std::is_integral_v<T> ? static_cast<T>(std::lround(v * 100 + 100))
                                              : static_cast<T>(v);
            char b[sizeof(T)];
            std::memcpy(b, &x, sizeof(T));
            std::reverse(b, b + sizeof(T));  // big-endian on disk
            bytes.insert(bytes.end(), b, b + sizeof(T));
          });
        }
    const std::string name = "vol_37x23x41_" + std::string(scalar_name(type)) + ".raw";
    const fs::path plain = dir_ / name;
    std::ofstream(plain, std::ios::binary)
        .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    const fs::path gz = dir_ / (name + ".gz");
    gzFile g = gzopen(gz.c_str(), "wb");
    gzwrite(g, bytes.data(), static_cast<unsigned>(bytes.size()));
    gzclose(g);
    RawOptions raw;
    raw.endian = Endian::Big;
    raw.spacing = Vec3d{0.5, 1.0, 1.5};
    const double iso = is_floating(type) ? 0.0 : 100.5;
    for (Method m : {Method::MarchingCubes, Method::DualContouring}) {
      ExtractOptions o = options(m, true);
      o.iso = iso;
      const std::string want = whole(plain.string(), o, MeshFormat::Ply, raw);
      ASSERT_GT(want.size(), 1000u);
      TiledResult r;
      EXPECT_EQ(tiled(plain.string(), o, MeshFormat::Ply, 4000, &r, raw), want)
          << name << " " << method_name(m);
      EXPECT_GT(r.plan.total(), 20);
      EXPECT_EQ(
          tiled(gz.string(), o, MeshFormat::Ply, plus_buffers(gz.string(), 100000, raw), &r, raw),
          want)
          << name << ".gz " << method_name(m);
      EXPECT_GE(r.plan.count[2], 2);  // slabs
      EXPECT_EQ(r.plan.count[0] * r.plan.count[1], 1);
    }
  }
}

// gzip'd slabs grown by a large halo overlap by 2 halo + 1 planes, which the source must keep:
// DC's Eno Hermite data (halo 4, 9 planes) and Macet max (halo 51 then; 138 now, so every Max
// slab's view is the whole volume and the budget sets only the slab count) once failed with "gzip'd
// slabs must be read in ascending z" when a fixed 8 planes were kept. Max's volume holds its
// surface in ten planes only: its search costs by the surface, and every slab searches the whole.
TEST_F(Tiler, GzipSlabsOverlapByTheirWholeHalo) {
  const Index3 dims{13, 11, 150};
  const Volume f = make_field_volume({FieldKind::Gyroid, 13});
  // A gyroid repeated along z in planes [lo, hi), samples of 0 (outside) elsewhere.
  auto write = [&](const std::string& stem, std::int64_t lo, std::int64_t hi) {
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]), 0);
    for (std::int64_t k = lo; k < hi; ++k)
      for (std::int64_t j = 0; j < dims[1]; ++j)
        for (std::int64_t i = 0; i < dims[0]; ++i)
          bytes[static_cast<std::size_t>(i + dims[0] * (j + dims[1] * k))] =
              static_cast<std::uint8_t>(std::lround(f.view().value(i, j, k % 13) * 100 + 100));
    const fs::path plain = dir_ / (stem + "_13x11x150_uint8.raw");
    std::ofstream(plain, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
    const fs::path gz = dir_ / (stem + "_13x11x150_uint8.raw.gz");
    gzFile g = gzopen(gz.c_str(), "wb");
    gzwrite(g, bytes.data(), static_cast<unsigned>(bytes.size()));
    gzclose(g);
    return std::pair{plain, gz};
  };
  const auto [long_plain, long_gz] = write("long", 0, dims[2]);
  const auto [band_plain, band_gz] = write("band", 70, 80);
  ExtractOptions eno = options(Method::DualContouring);
  eno.dc_hermite = DcHermite::Eno;
  eno.dc_solver = DcSolver::Qef;
  ExtractOptions max = options(Method::Macet);
  max.quality = MacetQuality::Max;
  for (ExtractOptions o : {eno, max}) {
    o.iso = 100.5;
    const bool is_max = o.method == Method::Macet;
    const fs::path& plain = is_max ? band_plain : long_plain;
    const fs::path& gz = is_max ? band_gz : long_gz;
    const std::string want = whole(plain.string(), o, MeshFormat::Ply);
    ASSERT_GT(want.size(), 1000u);
    TiledResult r;
    // Budgets that cut the volume into a few slabs (Max's halo makes its views the whole volume).
    const std::uint64_t memory = is_max ? 190000 : 60000;
    EXPECT_EQ(tiled(gz.string(), o, MeshFormat::Ply, plus_buffers(gz.string(), memory), &r), want)
        << method_name(o.method);
    EXPECT_GE(r.plan.count[2], 3) << method_name(o.method);
  }
}

// Macet's relaxation reads one sample more: random bytes hold many pinned samples.
TEST_F(Tiler, RelaxedMacetStreamsExactly) {
  std::mt19937 rng(3);
  std::vector<char> bytes(30 * 26 * 22);
  for (char& c : bytes) c = static_cast<char>(rng() & 0xff);
  const fs::path path = dir_ / "rnd_30x26x22_uint8.raw";
  std::ofstream(path, std::ios::binary)
      .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ExtractOptions o = options(Method::Macet, true);
  o.iso = 127.5;
  o.macet_relax = 0.3;
  const std::string want = whole(path.string(), o, MeshFormat::Ply);
  ASSERT_GT(want.size(), 10000u);
  TiledResult r;
  EXPECT_EQ(tiled(path.string(), o, MeshFormat::Ply, 60000, &r), want);
  EXPECT_GT(r.plan.total(), 8);
  o.macet_relax = 0;
  EXPECT_NE(whole(path.string(), o, MeshFormat::Ply), want);  // relaxation changed the mesh
}

// A brick whose real output overflows the budget is cut into z-slices; the file is unchanged.
TEST_F(Tiler, OverfullBricksAreSlicedWithoutChangingTheFile) {
  const std::string field = "field:gyroid:64";
  const ExtractOptions o = options(Method::MarchingCubes, true);
  TiledResult r;
  const std::string got = tiled(field, o, MeshFormat::Ply, 150000, &r);
  EXPECT_GT(r.bricks_extracted, r.plan.total());
  EXPECT_EQ(got, whole(field, o, MeshFormat::Ply));
}

// A budget that one-cell slices of a dense surface still overflow: TiledOptions::warn hears it
// once, before any brick is extracted, and the file is still exact. Macet counts its crossings
// (and their halo's) once the bricks are counted: torus 33's one-cell slices need about 76 kB.
TEST_F(Tiler, ABudgetTheSurfaceOverflowsIsSaidBeforeExtracting) {
  const std::string field = "field:torus:33";
  const ExtractOptions o = options(Method::Macet);
  const std::string want = whole(field, o, MeshFormat::Ply);
  for (std::uint64_t memory : {std::uint64_t{6000}, std::uint64_t{1} << 30}) {
    TiledOptions to;
    to.extract = o;
    to.memory = memory;
    to.max_read_amplification = 0;
    std::vector<std::string> said;
    bool extracting_before = false;  // an extraction report before the warning
    Progress progress([&](const ProgressUpdate& u) {
      if (u.stage == Stage::Extract && said.empty()) extracting_before = true;
      return true;
    });
    to.progress = &progress;
    to.warn = [&](const std::string& line) { said.push_back(line); };
    const fs::path out = dir_ / "warned.ply";
    const TiledResult r = extract_tiled(*open_volume_source(field, {}), to, out);
    EXPECT_EQ(slurp(out), want) << memory;
    if (memory == 6000) {
      // The tiler's tables of counts (16 bytes per sample row per brick column) are said first:
      // at this budget they alone exceed it.
      ASSERT_EQ(said.size(), 2u);
      EXPECT_NE(said[0].find("leaves out the tiler's tables of counts"), std::string::npos)
          << said[0];
      EXPECT_NE(said[1].find("memory budget of 6000 bytes is too small for this surface"),
                std::string::npos)
          << said[1];
      EXPECT_GT(r.largest_brick_bytes, memory);
      EXPECT_FALSE(extracting_before);
    } else {
      EXPECT_TRUE(said.empty());
      EXPECT_LE(r.largest_brick_bytes, memory);
    }
  }
}

TEST_F(Tiler, RealVolumeWithASmallBudget) {
  const fs::path engine = testing::shared_volume("engine_256x256x128_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(engine);
  // A plain copy, so bricks are true 3D bricks (a .gz source is read in slabs).
  const Volume v = read_volume(engine.string());
  const fs::path raw = dir_ / "engine_256x256x128_uint8.raw";
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(v.bytes()), static_cast<std::streamsize>(v.byte_size()));
  ExtractOptions o = options(Method::MarchingCubes);
  o.iso = 49.5;
  TiledResult r;
  // 8 MiB: cubes of about 100 cells, whose tables of counts (16 bytes per sample row per brick
  // column) stay within a quarter of the budget; at 1 MiB the bricks span whole rows instead.
  EXPECT_EQ(tiled(raw.string(), o, MeshFormat::Ply, 8 << 20, &r),
            whole(raw.string(), o, MeshFormat::Ply));
  EXPECT_GE(r.plan.total(), 8);
  EXPECT_GT(r.plan.count[0], 1);
  EXPECT_GT(r.plan.count[2], 1);
}

// NRRD with raw data attached, detached, after skipped bytes, and gzip'd (detached, and attached
// after the header: that one was read whole): read box by box.
TEST_F(Tiler, NrrdInputsStreamExactly) {
  const Volume f = make_field_volume({FieldKind::Torus, 29});
  std::string bytes;
  for (std::int64_t k = 0; k < 29; ++k)
    for (std::int64_t j = 0; j < 29; ++j)
      for (std::int64_t i = 0; i < 23; ++i) {
        const auto v = static_cast<std::int16_t>(std::lround(f.view().value(i, j, k) * 1000));
        bytes += static_cast<char>((v >> 8) & 0xff);  // big-endian
        bytes += static_cast<char>(v & 0xff);
      }
  const std::string head =
      "NRRD0004\ntype: int16\ndimension: 3\nsizes: 23 29 29\nendian: big\nspacings: 0.5 1 "
      "1.5\n";
  auto put = [&](const fs::path& p, const std::string& text) {
    std::ofstream(p, std::ios::binary)
        .write(text.data(), static_cast<std::streamsize>(text.size()));
  };
  put(dir_ / "attached.nrrd", head + "encoding: raw\n\n" + bytes);
  put(dir_ / "data.raw", bytes);
  put(dir_ / "detached.nhdr", head + "encoding: raw\ndata file: data.raw\n");
  put(dir_ / "skipped.bin", "0123456789" + bytes);
  put(dir_ / "skipped.nhdr", head + "encoding: raw\nbyte skip: -1\ndata file: skipped.bin\n");
  gzFile g = gzopen((dir_ / "data.raw.gz").c_str(), "wb");
  gzwrite(g, bytes.data(), static_cast<unsigned>(bytes.size()));
  gzclose(g);
  put(dir_ / "gzip.nhdr", head + "encoding: gzip\ndata file: data.raw.gz\n");
  put(dir_ / "gzip.nrrd", head + "encoding: gzip\n\n" + slurp(dir_ / "data.raw.gz"));
  ExtractOptions o = options(Method::MarchingCubes, true);
  o.iso = 50;
  for (const char* name :
       {"attached.nrrd", "detached.nhdr", "skipped.nhdr", "gzip.nhdr", "gzip.nrrd"}) {
    const std::string input = (dir_ / name).string();
    EXPECT_FALSE(open_volume_source(input, {})->in_memory()) << name;
    const std::string want = whole(input, o, MeshFormat::Ply);
    ASSERT_GT(want.size(), 1000u) << name;
    TiledResult r;
    EXPECT_EQ(tiled(input, o, MeshFormat::Ply, plus_buffers(input, 40000), &r), want) << name;
    EXPECT_GT(r.plan.total(), 3) << name;
  }
}

// An input that changes while an out-of-core run reads it twice (count, then extract) is named
// before anything is committed. Here the raw file's samples are scaled by 1.01 in place once the
// extraction has begun: the signs, so the counts, stay, and the mesh mixed bricks of both
// versions without an error.
TEST_F(Tiler, AnInputThatChangesDuringTheRunIsAnError) {
  const Volume f = make_field_volume({FieldKind::Sphere, 40});
  std::vector<float> samples(40 * 40 * 40);
  for (std::int64_t k = 0, i = 0; k < 40; ++k)
    for (std::int64_t j = 0; j < 40; ++j)
      for (std::int64_t x = 0; x < 40; ++x)
        samples[i++] = static_cast<float>(f.view().value(x, j, k));
  const fs::path file = dir_ / "s_40x40x40_float32.raw";
  auto put = [&](float scale) {
    std::vector<float> v = samples;
    for (float& x : v) x *= scale;
    std::ofstream out(file, std::ios::binary | std::ios::in | std::ios::out);
    if (!out) out.open(file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(4 * v.size()));
  };
  put(1);
  TiledOptions to;
  to.extract = options(Method::MarchingCubes);
  to.extract.iso = field_default_iso(FieldKind::Sphere);
  to.memory = 60000;
  bool changed = false;
  Progress progress([&](const ProgressUpdate& u) {
    if (u.stage == Stage::Extract && !changed) {
      changed = true;
      put(1.01f);
    }
    return true;
  });
  to.progress = &progress;
  const fs::path out = dir_ / "out.ply";
  try {
    const TiledResult r = extract_tiled(*open_volume_source(file.string(), {}), to, out);
    ADD_FAILURE() << "no error; " << r.plan.total() << " bricks";
  } catch (const InputError& e) {
    EXPECT_NE(
        std::string(e.what()).find("s_40x40x40_float32.raw: the input changed during the run"),
        std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(changed);
  EXPECT_FALSE(fs::exists(out));
  // Grown: a brick's read finds it, and the finding is said once (it was said again as where
  // "the run stopped at").
  fs::remove(file);
  put(1);
  changed = false;
  Progress growing([&](const ProgressUpdate& u) {
    if (u.stage == Stage::Extract && !changed) {
      changed = true;
      std::ofstream(file, std::ios::binary | std::ios::app) << std::string(1000, '\0');
    }
    return true;
  });
  to.progress = &growing;
  try {
    extract_tiled(*open_volume_source(file.string(), {}), to, out);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    const std::string what = e.what();
    const std::string said = "the input changed during the run";
    const std::size_t first = what.find(said);
    EXPECT_NE(first, std::string::npos) << what;
    EXPECT_EQ(what.find(said, first + 1), std::string::npos) << what;
  }
  EXPECT_TRUE(changed);
  EXPECT_FALSE(fs::exists(out));
}

// Macet max's halo (138 samples) against a budget for one-cell bricks of nucleon (41^3): 64,000
// bricks, each reading the whole volume, ran for ever. Refused, naming the smallest budget whose
// bricks read the volume at most 64 times over; that budget plans, one byte less does not.
TEST(BrickPlan, BricksThatWouldReadTheVolumeTooManyTimesOverAreRefused) {
  BrickPlanOptions o;
  o.halo = 138;
  o.state_bytes_per_sample = 4;
  o.volume_dims = {41, 41, 41};
  o.memory = brick_bytes({1, 1, 1}, o);
  std::string message;
  try {
    plan_bricks(o.volume_dims, o);
  } catch (const InputError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("bricks of 1x1x1 cells, each read with its halo, would read the volume "
                         "64000 times over (at most 64); give at least "),
            std::string::npos)
      << message;
  const std::string given = "give at least ";
  ASSERT_NE(message.find(given), std::string::npos);
  const std::uint64_t least = std::stoull(message.substr(message.find(given) + given.size()));
  o.memory = least;
  EXPECT_LE(read_amplification(plan_bricks(o.volume_dims, o), o.halo), 64);
  o.memory = least - 1;
  EXPECT_THROW(plan_bricks(o.volume_dims, o), InputError);
  EXPECT_EQ(least_memory(o.volume_dims, o), least);
  // Below one cell's need the refusal names the same budget (it named one cell's, which was then
  // refused for the reads).
  o.memory = 1000;
  try {
    plan_bricks(o.volume_dims, o);
    ADD_FAILURE() << "planned within 1000 bytes";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("one brick of one cell needs " +
                                         std::to_string(brick_bytes({1, 1, 1}, o)) +
                                         " bytes; give at least " + std::to_string(least) +
                                         " bytes (bricks that small, each read with its halo of "
                                         "138 samples, would read the volume more than 64 times"),
              std::string::npos)
        << e.what();
  }
  o.max_read_amplification = 0;  // no limit
  o.memory = brick_bytes({1, 1, 1}, o);
  EXPECT_EQ(least_memory(o.volume_dims, o), o.memory);
  EXPECT_EQ(plan_bricks(o.volume_dims, o).total(), 64000);
  // One brick reads the volume once; bricks of MC's halo (1) far from the limit.
  o.halo = 1;
  o.memory = ~std::uint64_t{0} >> 8;
  EXPECT_EQ(read_amplification(plan_bricks(o.volume_dims, o), o.halo), 1);
}

// Whole rows are preferred (their records are contiguous in the file), but not where a large halo
// makes them read the volume many times more over than cubes: Macet max on 2048x300x300 float32
// at 1.5653 GB read it 16.4 times over in rows of 2047 x 40 x 40 cells (1.27 at 1.5645 GB, in
// cubes).
TEST(BrickPlan, RowsGiveWayToCubesWhereTheHaloMakesThemReadMuchMore) {
  BrickPlanOptions o;
  o.halo = 138;
  o.sample_bytes = 4;
  o.state_bytes_per_sample = 4;
  o.volume_dims = {2048, 300, 300};
  for (const std::uint64_t memory : {std::uint64_t{1564500000}, std::uint64_t{1565300000}}) {
    o.memory = memory;
    const BrickPlan p = plan_bricks(o.volume_dims, o);
    EXPECT_LT(read_amplification(p, o.halo), 2)
        << memory << ": bricks of " << p.brick[0] << "x" << p.brick[1] << "x" << p.brick[2];
  }
  // A small halo keeps whole rows.
  o.halo = 1;
  o.state_bytes_per_sample = 0;
  o.memory = std::uint64_t{1} << 29;
  EXPECT_EQ(plan_bricks(o.volume_dims, o).brick[0], 2047);
}

// A brick whose z-slices overflow the budget however thin (the run goes over it, said once):
// cut into the fewest slices within a quarter above the least need of any slicing (where that need
// is twice the budget or more; else no more than it), not into one-cell
// slices, each of which re-reads the halo (Macet max's 138 samples: 329 parts of nucleon's 64
// bricks took 9.6-10.1 s, 131 parts 3.5-3.8 s).
TEST(BrickReaderSlicing, ABudgetNoSliceKeepsCutsTheFewestSlicesNearTheLeastNeed) {
  auto source = open_volume_source("field:torus:33", {});
  ExtractOptions e = options(Method::Macet);
  e.quality = MacetQuality::Max;
  const BrickReader reader(*source, e);
  const Box3 cells{{0, 0, 0}, {32, 32, 32}};
  const std::uint64_t vertices = 400000, faces = 800000;
  const std::int64_t depth = cells.extent(2);
  const std::vector<std::uint64_t> planes(static_cast<std::size_t>(depth), faces / 32);
  const BrickReader::Slicing s = reader.slice(cells, vertices, planes, 1000);
  // The least: the smallest need over every slicing, which a deep halo can put above one-cell
  // slices (the warning said one-cell slices needed 114,505 bytes, "with slices of up to
  // 97,900 bytes"). The faces are even over the planes, so the thickest slice needs the most.
  const auto thickest = [&](std::int64_t count) {
    Box3 part = cells;
    part.hi[2] = cells.lo[2] + (depth + count - 1) / count;
    const auto f = static_cast<std::uint64_t>(part.extent(2)) * (faces / 32);
    return reader.estimate(part, vertices * f / faces, f);
  };
  std::uint64_t least = thickest(1);
  for (std::int64_t count = 2; count <= depth; ++count) least = std::min(least, thickest(count));
  EXPECT_EQ(s.least, least);
  // (With the faces even over the planes, one-cell slices are the least here; before slices
  // were estimated with the faces their planes hold, rounding made a thicker slicing the least.)
  EXPECT_LE(least, thickest(depth));
  EXPECT_GE(s.bytes, s.least);
  EXPECT_GT(s.least, 1000u);
  EXPECT_LE(static_cast<double>(s.bytes), 1.25 * static_cast<double>(s.least));
  EXPECT_LT(s.count, depth);
  if (s.count > 1) {
    EXPECT_GT(static_cast<double>(thickest(s.count - 1)), 1.25 * static_cast<double>(s.least));
  }
  // A budget less than twice below the least (MC, whose estimate grows with a slice's
  // thickness): no slice above the least, so a hard limit the user counted on is passed by as
  // little as it can be.
  ExtractOptions mc = options(Method::MarchingCubes);
  const BrickReader mc_reader(*source, mc);
  const std::uint64_t mc_least = mc_reader.slice(cells, vertices, planes, 1).least;
  const BrickReader::Slicing near = mc_reader.slice(cells, vertices, planes, mc_least * 3 / 4);
  EXPECT_EQ(near.least, mc_least);
  EXPECT_LE(near.bytes, mc_least);
  // Where slices fit, the fewest that fit, as before.
  const BrickReader::Slicing fits = reader.slice(cells, vertices, planes, ~std::uint64_t{0} >> 8);
  EXPECT_EQ(fits.count, 1);
  EXPECT_EQ(fits.least, 0u);
}

// A brick whose faces crowd a few z-planes: each slice is estimated with the faces its planes
// hold, so every slice fits the budget (taken as an even share of the brick's faces, the slice
// holding them went over: bonsai tiled 4x4 at --memory 64MiB, simplified, one slice had 1.37
// times its estimate).
TEST(BrickReaderSlicing, EachSliceIsEstimatedWithTheFacesItsPlanesHold) {
  auto source = open_volume_source("field:torus:33", {});
  const BrickReader reader(*source, options(Method::MarchingCubes));
  const Box3 cells{{0, 0, 0}, {32, 32, 32}};
  std::vector<std::uint64_t> planes(32, 0);
  for (int z = 3; z < 7; ++z) planes[static_cast<std::size_t>(z)] = 50000;
  const std::uint64_t vertices = 100000, faces = 200000;
  const std::uint64_t memory = reader.estimate(cells, vertices, faces) / 3;
  const BrickReader::Slicing s = reader.slice(cells, vertices, planes, memory);
  ASSERT_GT(s.count, 1);
  std::uint64_t largest = 0;
  for (std::int64_t i = 0; i < s.count; ++i) {
    const Box3 part = z_slice(cells, i, s.count);
    std::uint64_t f = 0;
    for (std::int64_t z = part.lo[2]; z < part.hi[2]; ++z) f += planes[static_cast<std::size_t>(z)];
    const std::uint64_t need = reader.estimate(part, (vertices * f + faces - 1) / faces, f);
    EXPECT_LE(need, memory) << "slice " << i << " of " << s.count;
    largest = std::max(largest, need);
  }
  EXPECT_EQ(s.bytes, largest);
  // The slices tile the brick.
  EXPECT_EQ(z_slice(cells, 0, s.count).lo[2], cells.lo[2]);
  EXPECT_EQ(z_slice(cells, s.count - 1, s.count).hi[2], cells.hi[2]);
  EXPECT_THROW(reader.slice(cells, vertices, std::vector<std::uint64_t>(31, 0), memory), Error);
}

TEST_F(Tiler, VdbInputStreamsExactly) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(1.0f);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(0.25));
  auto acc = grid->getAccessor();
  const Volume f = make_field_volume({FieldKind::Sphere, 27});
  for (int k = 0; k < 27; ++k)
    for (int j = 0; j < 27; ++j)
      for (int i = 0; i < 27; ++i)
        acc.setValueOn(openvdb::Coord(i - 9, j + 4, k - 30),
                       static_cast<float>(f.view().value(i, j, k)));
  const fs::path file = dir_ / "sphere.vdb";
  openvdb::io::File out(file.string());
  out.write({grid});
  out.close();
  const ExtractOptions o = options(Method::DualContouring, true);
  TiledResult r;
  EXPECT_EQ(tiled(file.string(), o, MeshFormat::Ply, 12000, &r),
            whole(file.string(), o, MeshFormat::Ply));
  EXPECT_GT(r.plan.total(), 3);
}

TEST_F(Tiler, FailuresLeaveNoOutput) {
  // A gzip stream cut short: the error surfaces mid-extraction.
  const fs::path gz = dir_ / "cut_32x32x32_uint8.raw.gz";
  std::vector<unsigned char> bytes(32 * 32 * 32);
  for (std::size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<unsigned char>(i * 7);
  gzFile g = gzopen(gz.c_str(), "wb");
  gzwrite(g, bytes.data(), static_cast<unsigned>(bytes.size() / 2));
  gzclose(g);
  auto source = open_volume_source(gz.string(), {});
  TiledOptions to;
  to.extract = options(Method::MarchingCubes);
  to.extract.iso = 100;
  to.memory = 1 << 16;
  const fs::path out = dir_ / "out.ply";
  EXPECT_THROW(extract_tiled(*source, to, out), InputError);
  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().extension(), ".gz") << "left behind: " << e.path();
  // Budgets and formats that cannot work are refused before anything is written.
  to.memory = 10;
  EXPECT_THROW(extract_tiled(*open_volume_source("field:sphere:16", {}), to, out), InputError);
  to.memory = 1 << 20;
  to.format = MeshFormat::Obj;
  EXPECT_THROW(extract_tiled(*open_volume_source("field:sphere:16", {}), to, out), InputError);
  EXPECT_FALSE(fs::exists(out));
  // A raw file whose size disagrees with its name.
  const fs::path bad = dir_ / "bad_8x8x8_uint16.raw";
  std::ofstream(bad, std::ios::binary).write("abc", 3);
  EXPECT_THROW(open_volume_source(bad.string(), {}), InputError);
}

}  // namespace
}  // namespace isotile
