// The library's one extraction pipeline (tiler/pipeline.h), as a front end other than the CLI
// calls it (the MeshLab plugin's job: a file, auto iso, in core or under a memory budget,
// simplify, quality): the same mesh as extract() on the same volume, samples in memory giving
// the path's run, the out-of-core file equal to the in-core one, the options' Progress handed
// down, cancel leaving no file, and the errors before any output. The CLI's own tests check that
// `isotile extract` over it kept its behaviour.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/extract/marching_cubes.h"
#include "core/mesh/mesh_io.h"
#include "core/volume/itk_reader.h"
#include "core/volume/procedural_fields.h"
#include "skip_support.h"
#include "test_support.h"
#include "tiler/pipeline.h"
#include "tiler/source_histogram.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

class Pipeline : public testing::TempDirTest {
 protected:
  Pipeline() : TempDirTest("isotile-pipeline-") {}
};

PipelineInput input(const std::string& path, const VolumeView* volume = nullptr) {
  PipelineInput in;
  in.path = path;
  in.volume = volume;
  return in;
}

StatsJson steady(StatsJson j) {
  j.erase("seconds");
  j.erase("peak_rss_mb");
  return j;
}

TEST_F(Pipeline, InCoreIsExtractOnTheSameVolume) {
  const FieldSpec spec{FieldKind::Gyroid, 40};
  const Volume volume = make_field_volume(spec);
  for (const Method method : {Method::MarchingCubes, Method::Macet, Method::DualContouring}) {
    PipelineOptions o;
    o.extract.method = method;
    o.extract.backend = Backend::Cpu;
    o.stats = true;
    const PipelineResult r = run_pipeline(input("field:gyroid:40"), o);
    ExtractOptions e = o.extract;
    e.iso = field_default_iso(spec.kind);
    const Mesh want = extract(volume.view(), e);
    ASSERT_GT(want.triangles.size(), 1000u);
    EXPECT_EQ(r.mesh.positions, want.positions) << method_name(method);
    EXPECT_EQ(r.mesh.triangles, want.triangles) << method_name(method);
    EXPECT_EQ(r.triangles, want.triangles.size());
    EXPECT_EQ(r.stats["triangles"], want.triangles.size());
    EXPECT_EQ(r.stats["method"], method_name(method));
    EXPECT_TRUE(r.stats["output"].is_null());
    EXPECT_TRUE(r.stats.contains("distance_max"));  // a field's distance to its surface
    EXPECT_EQ(r.quality.triangles, want.triangles.size());
  }
}

TEST_F(Pipeline, SamplesInMemoryGiveThePathsRun) {
  const Volume volume = read_volume("field:torus:36");
  const VolumeView view = volume.view();
  PipelineOptions o;
  o.iso_auto = true;
  o.stats = true;
  o.extract.method = Method::DualContouring;
  const PipelineResult a = run_pipeline(input("field:torus:36"), o);
  const PipelineResult b = run_pipeline(input("field:torus:36", &view), o);
  ASSERT_TRUE(a.auto_iso.has_value());
  EXPECT_EQ(a.iso, b.iso);
  EXPECT_EQ(a.mesh.positions, b.mesh.positions);
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles);
  EXPECT_EQ(steady(a.stats), steady(b.stats));
  EXPECT_EQ(a.stats["iso_auto"]["rule"], "otsu");
}

TEST_F(Pipeline, OutOfCoreWritesTheInCoreFileAndReportsEveryBrick) {
  PipelineOptions in_core;
  in_core.output = (dir_ / "in.ply").string();
  in_core.keep_mesh = false;
  const PipelineResult a = run_pipeline(input("field:gyroid:64"), in_core);
  EXPECT_TRUE(a.mesh.positions.empty());  // not kept
  std::vector<ProgressUpdate> updates;
  Progress progress([&](const ProgressUpdate& u) {
    updates.push_back(u);
    return true;
  });
  PipelineOptions tiled = in_core;
  tiled.output = (dir_ / "out.ply").string();
  tiled.memory = "256KiB";
  tiled.stats = true;
  tiled.progress = &progress;
  std::vector<std::string> log;
  tiled.log = [&](const std::string& line) { log.push_back(line); };
  const PipelineResult b = run_pipeline(input("field:gyroid:64"), tiled);
  ASSERT_GT(b.bricks, 4);
  EXPECT_EQ(slurp(dir_ / "out.ply"), slurp(dir_ / "in.ply"));
  EXPECT_EQ(b.triangles, a.triangles);
  EXPECT_EQ(b.stats["bricks"], b.bricks);
  EXPECT_EQ(b.stats["memory_budget"], 256u * 1024);
  std::int64_t extracted = 0;
  for (const ProgressUpdate& u : updates)
    if (u.stage == Stage::Extract && u.fraction == 1) ++extracted;
  EXPECT_EQ(extracted, b.bricks);
  ASSERT_FALSE(log.empty());
  EXPECT_NE(log.front().find("brick by brick within 256KiB"), std::string::npos) << log.front();
}

TEST_F(Pipeline, ThePluginsRunAutoIsoUnderABudgetWithSimplification) {
  PipelineOptions o;
  o.iso_auto = true;
  o.memory = "256KiB";
  o.simplify = 0.5;
  o.quality = true;  // the radius ratios alone, as the plugin shows them
  o.output = (dir_ / "job.ply").string();
  const PipelineResult r = run_pipeline(input("field:sphere:48"), o);
  EXPECT_GT(r.bricks, 1);
  EXPECT_LT(r.triangles, r.triangles_extracted);
  EXPECT_EQ(r.quality.triangles, r.triangles);
  EXPECT_GT(r.quality.mean, 0.5);
  EXPECT_TRUE(r.stats.is_null());
  const Mesh back = read_mesh(dir_ / "job.ply");
  EXPECT_EQ(back.triangles.size(), r.triangles);
  // In core, the mesh comes back with its measures.
  o.memory.clear();
  o.output.clear();
  const PipelineResult c = run_pipeline(input("field:sphere:48"), o);
  EXPECT_EQ(c.quality.triangles, c.mesh.triangles.size());
  EXPECT_EQ(c.triangles_extracted, r.triangles_extracted);
}

// The run's warnings go to PipelineOptions::warn where a front end sets it (the plugin's log,
// Python's warnings), else to stderr as the CLI prints them: here a budget that Macet's one-cell
// slices of torus 33 overflow (tests/test_tiler.cpp), said once; the file is still exact.
TEST_F(Pipeline, WarningsGoWhereTheFrontEndSaysElseToStderr) {
  PipelineOptions o;
  o.extract.method = Method::Macet;
  o.output = (dir_ / "whole.ply").string();
  run_pipeline(input("field:torus:33"), o);
  o.memory = "12000";  // above 8341 bytes, where its bricks would read the volume 64 times over
  o.output = (dir_ / "warned.ply").string();
  std::vector<std::string> said;
  o.warn = [&](const std::string& line) { said.push_back(line); };
  ::testing::internal::CaptureStderr();
  run_pipeline(input("field:torus:33"), o);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
  // The tiler's tables of counts first (at this budget they alone exceed it), then the surface.
  ASSERT_EQ(said.size(), 2u);
  EXPECT_EQ(said[0].rfind("the memory budget of 12000 bytes leaves out the tiler's tables", 0), 0u)
      << said[0];
  EXPECT_EQ(said[1].rfind("the memory budget of 12000 bytes is too small for this surface", 0), 0u)
      << said[1];
  EXPECT_EQ(slurp(dir_ / "warned.ply"), slurp(dir_ / "whole.ply"));
  o.warn = nullptr;
  ::testing::internal::CaptureStderr();
  run_pipeline(input("field:torus:33"), o);
  EXPECT_EQ(::testing::internal::GetCapturedStderr(),
            "isotile: warning: " + said[0] + "\nisotile: warning: " + said[1] + "\n");
}

// The samples' range (options.range) comes back for a front end to show, from what the run read:
// in core one pass or iso_auto's histogram, out of core the histogram.
TEST_F(Pipeline, ReportsTheSamplesRange) {
  const std::string nucleon = std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz";
  const std::pair<double, double> range = value_range(read_volume(nucleon).view());
  ASSERT_LT(range.first, range.second);
  PipelineOptions o;
  o.iso = 60.5;
  EXPECT_FALSE(run_pipeline(input(nucleon), o).range.has_value());  // not asked for
  o.range = true;
  const PipelineResult in_core = run_pipeline(input(nucleon), o);
  ASSERT_TRUE(in_core.range.has_value());
  EXPECT_EQ(*in_core.range, range);
  o.iso_auto = true;
  EXPECT_EQ(run_pipeline(input(nucleon), o).range, range);
  o.memory = "256KiB";
  o.output = (dir_ / "m.ply").string();
  const PipelineResult bricked_auto = run_pipeline(input(nucleon), o);
  EXPECT_GT(bricked_auto.bricks, 1);
  EXPECT_EQ(bricked_auto.range, range);
  // Out of core without iso_auto: no second pass over the file for it.
  o.iso_auto = false;
  EXPECT_FALSE(run_pipeline(input(nucleon), o).range.has_value());
}

// A DICOM series' UID and description come back from the headers the run read, in core and out
// of core, for a front end that names the series (the MeshLab plugin's layer).
TEST_F(Pipeline, ReportsTheDicomSeries) {
  PipelineOptions o;
  o.iso = 60.5;
  const PipelineResult raw =
      run_pipeline(input(std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz"), o);
  EXPECT_TRUE(raw.series_uid.empty());  // not DICOM
  EXPECT_TRUE(raw.series_description.empty());
  const fs::path dicom = fs::path(ISOTILE_SHARED_DATA) / "dicom_uih_t1_head_slab/00000060.dcm";
  if (!fs::exists(dicom)) ISOTILE_SKIP(SharedData, "no shared data at " << dicom);
  if (!itk_available()) ISOTILE_SKIP(Itk, "built without ITK");
  const VolumeHeader h = read_volume_header(dicom.string());
  ASSERT_FALSE(h.series_description.empty());
  ASSERT_FALSE(h.series_uid.empty());
  PipelineOptions d;
  d.iso = 300;
  d.keep_mesh = false;
  const PipelineResult whole = run_pipeline(input(dicom.string()), d);
  EXPECT_EQ(whole.series_uid, h.series_uid);
  EXPECT_EQ(whole.series_description, h.series_description);
  d.memory = "64MiB";
  d.output = (dir_ / "d.ply").string();
  const PipelineResult bricked = run_pipeline(input(dicom.string()), d);
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.series_uid, h.series_uid);
  EXPECT_EQ(bricked.series_description, h.series_description);
}

// No surface: the CLI's message, and its finding for a front end with other ways out.
TEST_F(Pipeline, NoSurfaceSaysWhereTheSamplesLie) {
  const std::string nucleon = std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz";
  const std::pair<double, double> range = value_range(read_volume(nucleon).view());
  std::ostringstream finding;
  finding << "the samples range from " << range.first << " to " << range.second << ", all below it";
  for (const char* memory : {"", "256KiB"}) {
    PipelineOptions o;
    o.iso = 1000;
    o.memory = memory;
    if (*memory) o.output = (dir_ / "m.ply").string();
    try {
      run_pipeline(input(nucleon), o);
      ADD_FAILURE() << "no error";
    } catch (const NoSurfaceError& e) {
      EXPECT_EQ(e.iso, 1000);
      EXPECT_EQ(e.range, range);
      EXPECT_EQ(e.finding, finding.str());
      EXPECT_EQ(std::string(e.what()), "no surface at iso 1000: " + finding.str() +
                                           "; choose an isovalue inside the range, or --iso "
                                           "auto (or --allow-empty to write the empty mesh)");
    }
  }
  // Every number as it reads back: at ten digits an isovalue just above the largest sample read
  // "no surface at iso 255: the samples range from 0 to 255, all below it".
  PipelineOptions above;
  above.iso = range.second + 1e-9;
  try {
    run_pipeline(input(nucleon), above);
    ADD_FAILURE() << "no error";
  } catch (const NoSurfaceError& e) {
    EXPECT_NE(std::string(e.what()).find("no surface at iso " + std::to_string(int(range.second)) +
                                         ".000000001: "),
              std::string::npos)
        << e.what();
  }
  // Under --iso auto the way out is not --iso auto (a column of 2x2 samples: Dual Contouring
  // makes no face where the surface meets only the volume's border).
  Volume column(ScalarType::Int16, {2, 2, 12});
  for (std::int64_t i = 0; i < column.sample_count(); ++i)
    column.data<std::int16_t>()[i] = static_cast<std::int16_t>(i < 24 ? -1000 : 1000);
  for (const char* memory : {"", "256KiB"}) {
    PipelineOptions o;
    o.iso_auto = true;
    o.extract.method = Method::DualContouring;
    o.memory = memory;
    PipelineInput in;
    in.path = (dir_ / "column_2x2x12_int16.raw").string();
    std::ofstream(in.path, std::ios::binary)
        .write(reinterpret_cast<const char*>(column.bytes()),
               static_cast<std::streamsize>(column.byte_size()));
    if (*memory) o.output = (dir_ / "m.ply").string();
    try {
      run_pipeline(in, o);
      ADD_FAILURE() << "no error";
    } catch (const NoSurfaceError& e) {
      EXPECT_EQ(std::string(e.what()), "no surface at iso " + number_text(e.iso) +
                                           " (the isovalue --iso auto chose): " + e.finding +
                                           "; choose another method or an isovalue with --iso, or "
                                           "--allow-empty to write the empty mesh");
      EXPECT_TRUE(e.straddled);
    }
    fs::remove(in.path);
  }
  EXPECT_TRUE(fs::is_empty(dir_));
}

// The fifth call answers false. Bricks in flight at once may each have a call waiting for the
// callback's lock when it does (core/progress.h: one call at a time): at most one more per thread.
TEST_F(Pipeline, CancelStopsTheRunAndLeavesNoFile) {
  int calls = 0;
  Progress progress([&](const ProgressUpdate&) { return ++calls < 5; });
  PipelineOptions o;
  o.output = (dir_ / "m.ply").string();
  o.memory = "256KiB";
  o.progress = &progress;
  EXPECT_THROW(run_pipeline(input("field:gyroid:64"), o), Cancelled);
  EXPECT_GE(calls, 5);
  EXPECT_LE(calls, 5 + tbb::this_task_arena::max_concurrency());
  EXPECT_TRUE(fs::is_empty(dir_));
}

// A stand-in for a GL backend whose start (its context, made on a thread while the volume is
// read: start_backend()) fails once `g_start_fails` is set; until then it runs the CPU's Marching
// Cubes.
std::atomic<bool> g_start_fails{false};
Mesh stand_in_run(const VolumeView& view, const ExtractOptions& o, GpuReport*) {
  return marching_cubes(
      view, {.iso = o.iso, .normals = o.normals, .cells = o.cells, .progress = o.progress});
}
std::string stand_in_probe(bool* hardware, bool) {
  *hardware = true;
  return "";
}
void stand_in_start() {}
std::string stand_in_failure() {
  return g_start_fails ? "no usable OpenGL 4.5 context (the stand-in's)" : "";
}

// The start failing during the read stops the run at the next report with the backend's error,
// not after the read; in core and out of core, and nothing is written.
TEST_F(Pipeline, ABackendWhoseStartFailsStopsTheReadWithItsError) {
  register_backend(Backend::HistoPyramid, {stand_in_run, stand_in_run, stand_in_run},
                   stand_in_probe, stand_in_start, stand_in_failure);
  const Volume volume = make_field_volume({FieldKind::Sphere, 48});
  const fs::path raw =
      dir_ / ("sphere_48x48x48_" + std::string(scalar_name(volume.view().type)) + ".raw");
  {
    std::ofstream out(raw, std::ios::binary);
    out.write(reinterpret_cast<const char*>(volume.bytes()),
              static_cast<std::streamsize>(volume.byte_size()));
  }
  for (const std::string memory : {"", "256KiB"}) {
    SCOPED_TRACE("memory '" + memory + "'");
    PipelineOptions o;
    o.extract.backend = Backend::HistoPyramid;
    o.iso = field_default_iso(FieldKind::Sphere);
    o.memory = memory;
    o.output = (dir_ / "m.ply").string();
    double read = 0;
    int reports = 0;
    // The start fails at the run's first report (the read's start, in core).
    Progress progress([&](const ProgressUpdate& u) {
      if (u.stage == Stage::Read) read = std::max(read, u.fraction);
      g_start_fails = ++reports == 1 || g_start_fails;
      return true;
    });
    o.progress = &progress;
    g_start_fails = false;
    try {
      run_pipeline(input(raw.string()), o);
      ADD_FAILURE() << "the run went on";
    } catch (const InputError& e) {
      EXPECT_STREQ(e.what(), "backend 'hp': no usable OpenGL 4.5 context (the stand-in's)");
    }
    EXPECT_EQ(reports, 1);
    EXPECT_LT(read, 1.0);
    EXPECT_FALSE(fs::exists(o.output));

    // The same run, the start not failing: it runs to the end.
    Progress quiet;
    o.progress = &quiet;
    g_start_fails = false;
    EXPECT_GT(run_pipeline(input(raw.string()), o).triangles, 100);
    EXPECT_TRUE(fs::exists(o.output));
    fs::remove(o.output);
    // Failed before the run (the probe says nothing of it here): the first report stops it.
    g_start_fails = true;
    EXPECT_THROW(run_pipeline(input(raw.string()), o), InputError);
    EXPECT_FALSE(fs::exists(o.output));
  }
  g_start_fails = false;
}

TEST_F(Pipeline, TheWrittenCallbackSeesTheMeshAsWritten) {
  PipelineOptions o;
  o.output = (dir_ / "m.ply").string();
  std::size_t seen = 0;
  o.written = [&](const Mesh& m) { seen = m.triangles.size(); };
  const PipelineResult r = run_pipeline(input("field:sphere:24"), o);
  EXPECT_GT(seen, 100u);
  EXPECT_EQ(seen, r.mesh.triangles.size());
  EXPECT_EQ(read_mesh(dir_ / "m.ply").triangles.size(), seen);
}

TEST_F(Pipeline, BadOptionsFailBeforeAnyOutput) {
  const auto fails = [&](const PipelineInput& in, const PipelineOptions& o, const char* text) {
    try {
      run_pipeline(in, o);
      ADD_FAILURE() << "no error, expected: " << text;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
    }
  };
  PipelineOptions o;
  o.memory = "1MiB";
  fails(input("field:sphere:16"), o, "give an output");
  const Volume volume = read_volume("field:sphere:16");
  const VolumeView view = volume.view();
  o.output = (dir_ / "m.ply").string();
  fails(input("field:sphere:16", &view), o, "reads its input from a file");
  o = {};
  fails(input((dir_ / "v_8x8x8_uint8.raw").string()), o, "--iso is required");
  o.iso = 0;
  o.extract.macet_relax = 0.2;
  fails(input("field:sphere:16"), o, "--macet-relax applies to --method macet only");
  o.extract.macet_relax = 0;
  // Every method's own options away from their defaults, with another method.
  o.extract.keep_quads = true;
  fails(input("field:sphere:16"), o, "--quads applies to --method dc only");
  o.extract.method = Method::Macet;
  fails(input("field:sphere:16"), o, "--quads applies to --method dc only");
  o.extract.keep_quads = false;
  o.extract.dc_solver = DcSolver::Qef;
  fails(input("field:sphere:16"), o, "--dc-solver applies to --method dc only");
  o.extract.dc_solver = DcSolver::MassPoint;
  o.extract.dc_hermite = DcHermite::Eno;
  fails(input("field:sphere:16"), o, "--dc-hermite applies to --method dc only");
  o.extract.dc_hermite = DcHermite::Central;
  o.extract.dc_vertices = DcVertices::Cell;
  fails(input("field:sphere:16"), o, "--dc-vertices applies to --method dc only");
  o.extract.dc_vertices = DcVertices::Patch;
  o.extract.method = Method::DualContouring;
  o.extract.quality = MacetQuality::Max;
  fails(input("field:sphere:16"), o, "--quality applies to --method macet only");
  o.extract.quality = MacetQuality::Fast;
  o.extract.method = Method::MarchingCubes;
  o.extract.macet_relax = 0.7;
  fails(input("field:sphere:16"), o, "macet_relax must be in [0, 0.5)");
  o = {};
  o.simplify = 0;
  fails(input("field:sphere:16"), o, "simplify must be in (0, 1]");
  o = {};
  o.output = (dir_ / "m.xyz").string();
  EXPECT_ANY_THROW(run_pipeline(input("field:sphere:16"), o));
  EXPECT_TRUE(fs::is_empty(dir_));
}

}  // namespace
}  // namespace isotile
