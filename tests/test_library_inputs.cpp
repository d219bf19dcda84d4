// The C++ library's entry points refuse what makes no mesh, as the CLI and the pipeline do,
// instead of a wrong mesh without a word or a crash: extract(), macet(), dual_contouring() on a
// caller's view; read_volume()'s overrides; extract_tiled(); plan_bricks(); enums cast from
// numbers. Each case below made a flat, inside-out, NaN or empty mesh, read out of bounds, or
// wrote an empty or mislabelled file before these checks.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/extract/macet.h"
#include "core/mesh/mesh_io.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"
#include "tiler/brick_plan.h"
#include "tiler/tiled_extract.h"
#include "tiler/volume_source.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// `call` throws InputError whose message holds `says`.
template <class F>
void refuses(F&& call, const std::string& says, const std::string& what) {
  try {
    call();
    ADD_FAILURE() << what << ": no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << what << ": " << e.what();
  }
}

class LibraryInputs : public testing::TempDirTest {
 protected:
  LibraryInputs() : TempDirTest("isotile-library-") {}
  Volume ball_ = make_field_volume(*parse_field_spec("field:sphere:16"));
  const double iso_ = field_default_iso(FieldKind::Sphere);
};

TEST_F(LibraryInputs, ExtractionRefusesAViewOrIsovalueThatMakesNoMesh) {
  const auto with = [&](auto edit) {
    VolumeView v = ball_.view();
    edit(v);
    return v;
  };
  struct Case {
    VolumeView view;
    double iso;
    const char* says;
  };
  const std::vector<Case> cases = {
      {with([](VolumeView& v) {
         v.spacing = {0, 1, 1};
       }),
       iso_, "spacing must be finite"},
      {with([](VolumeView& v) {
         v.spacing = {-1, 1, 1};
       }),
       iso_, "spacing must be finite"},
      {with([](VolumeView& v) {
         v.spacing = {kNaN, 1, 1};
       }),
       iso_, "spacing must be finite"},
      {with([](VolumeView& v) {
         v.origin = {0, kInf, 0};
       }),
       iso_, "origin is not finite"},
      {with([](VolumeView& v) { v.data = nullptr; }), iso_, "without data (a null pointer)"},
      {with([](VolumeView& v) { v.dims[0] = -4; }), iso_, "dims must not be negative"},
      {with([](VolumeView& v) { v.type = static_cast<ScalarType>(42); }), iso_,
       "unknown scalar type 42"},
      {ball_.view(), kNaN, "--iso must be a finite number"},
      {ball_.view(), -kInf, "--iso must be a finite number"},
  };
  for (const Case& c : cases) {
    for (Method m : {Method::MarchingCubes, Method::Macet, Method::DualContouring}) {
      ExtractOptions o{.iso = c.iso};
      o.method = m;
      o.backend = Backend::Cpu;
      refuses([&] { extract(c.view, o); }, c.says, std::string(c.says) + " (extract)");
    }
    refuses([&] { macet(c.view, {.iso = c.iso}); }, c.says, std::string(c.says) + " (macet)");
    refuses([&] { dual_contouring(c.view, {.iso = c.iso}); }, c.says,
            std::string(c.says) + " (dual_contouring)");
  }
  ExtractOptions o{.iso = iso_};
  o.method = static_cast<Method>(7);
  refuses([&] { extract(ball_.view(), o); }, "unknown method 7", "method 7");
  refuses([&] { method_name(static_cast<Method>(7)); }, "unknown method 7", "method_name");
  // The view as read gives its mesh.
  EXPECT_GT(extract(ball_.view(), ExtractOptions{.iso = iso_}).triangles.size(), 100u);
}

TEST_F(LibraryInputs, ReadingRefusesOverridesThatMakeNoMesh) {
  const fs::path raw = dir_ / "ball_16x16x16_float32.raw";
  std::ofstream(raw, std::ios::binary)
      .write(reinterpret_cast<const char*>(ball_.bytes()),
             static_cast<std::streamsize>(ball_.byte_size()));
  for (const std::string input : {std::string("field:sphere:16"), raw.string()}) {
    refuses(
        [&] {
          read_volume(input, {.spacing = Vec3d{0, 1, 1}});
        },
        "--spacing must be three finite numbers above 0, got 0,1,1", input);
    refuses(
        [&] {
          read_volume(input, {.spacing = Vec3d{1, -1, 1}});
        },
        "--spacing must be three finite numbers above 0", input);
    refuses(
        [&] {
          read_volume(input, {.origin = Vec3d{kNaN, 0, 0}});
        },
        "--origin must be three finite numbers", input);
    refuses(
        [&] {
          read_volume_header(input, {.spacing = Vec3d{1, 1, kNaN}});
        },
        "--spacing must be three finite numbers above 0", input);
    refuses(
        [&] {
          open_volume_source(input, {.spacing = Vec3d{0, 0, 0}}, 1 << 20);
        },
        "--spacing must be three finite numbers above 0", input);
  }
  refuses([&] { read_volume(raw.string(), {.type = static_cast<ScalarType>(42)}); },
          "unknown scalar type 42", "type 42");
  EXPECT_EQ(read_volume(raw.string(), {.spacing = Vec3d{2, 1, 1}}).spacing()[0], 2);
}

TEST_F(LibraryInputs, TheTilerRefusesWhatThePipelineRefuses) {
  const fs::path out = dir_ / "tiled.ply";
  const auto tiled = [&](auto edit, const fs::path& to) {
    auto source = open_volume_source("field:sphere:48", {}, 1 << 20);
    TiledOptions o;
    o.memory = 1 << 20;
    o.extract.iso = iso_;
    edit(*source, o);
    extract_tiled(*source, o, to);
  };
  refuses(
      [&] {
        tiled([](VolumeSource& s, TiledOptions&) { s.spacing = {kNaN, 1, 1}; }, out);
      },
      "spacing must be finite", "NaN spacing");
  refuses(
      [&] {
        tiled([](VolumeSource& s, TiledOptions&) { s.spacing = {0, 1, 1}; }, out);
      },
      "spacing must be finite", "zero spacing");
  refuses([&] { tiled([](VolumeSource&, TiledOptions& o) { o.extract.iso = kNaN; }, out); },
          "--iso must be a finite number", "NaN iso");
  for (const double ratio : {kNaN, 1.5, 0.0})
    refuses([&] { tiled([&](VolumeSource&, TiledOptions& o) { o.simplify = ratio; }, out); },
            "simplify must be in (0, 1]", "simplify " + std::to_string(ratio));
  refuses([&] { tiled([](VolumeSource&, TiledOptions&) {}, dir_ / "tiled.stl"); },
          "tiled.stl: its extension names another format than PLY", "PLY into .stl");
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(dir_ / "tiled.stl"));
  tiled([](VolumeSource&, TiledOptions& o) { o.format = MeshFormat::Stl; }, dir_ / "tiled.stl");
  EXPECT_GT(read_mesh(dir_ / "tiled.stl").triangles.size(), 100u);
}

TEST_F(LibraryInputs, PlansAndFormatsOutsideTheirRangeAreRefused) {
  BrickPlanOptions o;
  o.memory = 1 << 20;
  refuses(
      [&] {
        plan_bricks({0, 0, 0}, o);
      },
      "the volume's dims must be positive, got 0x0x0", "dims 0");
  refuses([&] { plan_bricks({-4, 10, 10}, o); }, "dims must be positive", "dims -4");
  BrickPlanOptions bad = o;
  bad.halo = -5;
  refuses([&] { plan_bricks({10, 10, 10}, bad); }, "a negative halo", "halo -5");
  bad = o;
  bad.sample_bytes = 0;
  refuses([&] { plan_bricks({10, 10, 10}, bad); }, "samples of 0 bytes", "0 bytes");
  const std::int64_t huge = std::int64_t{1} << 40;
  EXPECT_THROW(plan_bricks({huge, huge, huge}, o), CapacityError);
  EXPECT_EQ(plan_bricks({10, 10, 10}, o).total(), 1);

  Mesh tri;
  tri.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  tri.triangles = {{0, 1, 2}};
  refuses([&] { write_mesh(tri, dir_ / "x.ply", {.format = static_cast<MeshFormat>(9)}); },
          "unknown mesh format 9", "format 9");
  EXPECT_FALSE(fs::exists(dir_ / "x.ply"));
  refuses([&] { scalar_size(static_cast<ScalarType>(200)); }, "unknown scalar type 200",
          "type 200");
  // Macet max's sweeps: INT_MAX took minutes in macet_halo() alone (the reach grows with their
  // square) and overflowed it.
  MacetOptions sweeps{.quality = MacetQuality::Max, .max_sweeps = std::numeric_limits<int>::max()};
  refuses([&] { macet_halo(sweeps); }, "max_sweeps must be in [0, 100]", "INT_MAX sweeps");
  sweeps.max_sweeps = 100;
  EXPECT_GT(macet_halo(sweeps), macet_halo({.quality = MacetQuality::Max}));
}

}  // namespace
}  // namespace isotile
