// The MeshLab filters' Qt-free part: fields to library calls, and the messages a MeshLab user
// sees for bad fields (runs in every build, sanitizers included).
#include "meshlab_plugin/isosurface_job.h"

#include <fnmatch.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <iterator>
#include <vector>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_topology.h"
#include "core/volume/itk_reader.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/volume_io.h"
#include "skip_support.h"
#include "test_support.h"
#include "tiler/pipeline.h"

namespace isotile::meshlab {
namespace {

const std::string kNucleon = std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz";

IsosurfaceParams nucleon() {
  IsosurfaceParams p;
  p.file = kNucleon;
  p.iso = 60.5;
  return p;
}

// A folder of each test's own for the brick-by-brick runs' private folders (the shared temporary
// folder may hold other runs' folders meanwhile), removed afterwards even when a test fails.
class MeshlabJob : public isotile::testing::TempDirTest {
 protected:
  MeshlabJob() : TempDirTest("isotile-job-") {}
};

std::string message_of(const IsosurfaceParams& p) {
  try {
    run_isosurface(p, "", {});
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

TEST_F(MeshlabJob, ExtractsNamesTheLayerAndReportsProgress) {
  IsosurfaceParams p = nucleon();
  p.method = 1;
  double last = -1;
  bool ordered = true;
  std::vector<std::string> stages;  // each stage once, in the order they came
  const IsosurfaceResult r = run_isosurface(p, "", [&](const std::string& stage, double fraction) {
    ordered = ordered && fraction >= last && fraction <= 1;
    last = fraction;
    if (stages.empty() || stages.back() != stage) stages.push_back(stage);
  });
  EXPECT_TRUE(ordered);
  EXPECT_GT(last, 0.5);
  ASSERT_EQ(stages.size(), 2u);
  EXPECT_EQ(stages.front(), "reading nucleon_41x41x41_uint8.raw.gz");
  EXPECT_EQ(stages[1], "extracting (macet)");
  EXPECT_GT(r.mesh.triangles.size(), 1000u);
  // No dot for MeshLab's layer list to cut at; the full story goes to the log.
  EXPECT_EQ(r.layer_name, "nucleon_41x41x41_uint8 macet iso60_5");
  EXPECT_EQ(r.description, kNucleon + ", Macet fast, isovalue 60.5");
  ASSERT_TRUE(r.range.has_value());
  EXPECT_EQ(*r.range, value_range(read_volume(kNucleon).view()));
  EXPECT_EQ(r.backend, "cpu");
  EXPECT_EQ(r.bricks, 1);
  EXPECT_GT(r.quality.mean, 0.8);
  EXPECT_EQ(r.quality.triangles, r.mesh.triangles.size());
}

TEST_F(MeshlabJob, LayerNamesHaveNoDotsAndDifferWhenTaken) {
  EXPECT_EQ(layer_name("/data/ch2.nii.gz", "", "macet", 60.5), "ch2 macet iso60_5");
  EXPECT_EQ(layer_name("v_8x8x8_float32.raw", "", "mc", -0.25), "v_8x8x8_float32 mc iso-0_25");
  EXPECT_EQ(layer_name("/d/scan.v2.nrrd", "", "dc", 3), "scan_v2 dc iso3");
  EXPECT_EQ(layer_name("/d/1-001.dcm", "T1 3D/SAG 1.0mm", "mc", 300), "T1 3D_SAG 1_0mm mc iso300");
  EXPECT_EQ(layer_name("/d/series/", "", "mc", 1), "series mc iso1");
  // Extensions in any case (the file dialog offers *.TIF, *.DCM).
  EXPECT_EQ(layer_name("/d/EMBRYO.TIF", "", "mc", 35), "EMBRYO mc iso35");
  EXPECT_EQ(layer_name("NUC_41x41x41_uint8.RAW.GZ", "", "mc", 35), "NUC_41x41x41_uint8 mc iso35");
  // Ten digits: 1234567.5 and 1234570 are other layers' names (%g made both iso1_23457e+06).
  EXPECT_EQ(layer_name("big.raw", "", "mc", 1234567.5), "big mc iso1234567_5");
  const std::vector<std::string> layers = {"a mc iso1", "a mc iso1 (2)"};
  auto taken = [&](const std::string& n) {
    return std::find(layers.begin(), layers.end(), n) != layers.end();
  };
  EXPECT_EQ(unique_name("b mc iso1", taken), "b mc iso1");
  EXPECT_EQ(unique_name("a mc iso1", taken), "a mc iso1 (3)");
}

// The file dialog's patterns cover every extension the readers know, and the shipped script
// lists them as the filter declares them.
TEST_F(MeshlabJob, FilePatternsCoverEveryFormat) {
  auto matched = [](const std::string& name) {
    for (const char* pattern : kVolumeFilePatterns)
      if (std::string(pattern) != "*" && ::fnmatch(pattern, name.c_str(), 0) == 0) return true;
    return false;
  };
  for (const char* name : {"a.raw",  "a.raw.gz", "a.nrrd", "a.nhdr", "a.vdb", "a.nii",  "a.nii.gz",
                           "a.mha",  "a.mhd",    "a.tif",  "a.tiff", "a.mrc", "a.mrcs", "a.map",
                           "a.ccp4", "a.map.gz", "a.dcm",  "a.ima",  "a.IMA", "a.DCM"})
    EXPECT_TRUE(matched(name)) << name;
  std::ifstream in(ISOTILE_MESHLAB_EXAMPLE);
  const std::string example((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::size_t n = std::size(kVolumeFilePatterns);
  std::string declared = "exts_cardinality=\"" + std::to_string(n) + "\"";
  for (std::size_t i = 0; i < n; ++i)
    declared += " exts_val" + std::to_string(i) + "=\"" + kVolumeFilePatterns[i] + "\"";
  EXPECT_NE(example.find(declared), std::string::npos)
      << "the example should declare: " << declared;
}

TEST_F(MeshlabJob, NoSurfaceNamesTheRangeInCoreAndBrickByBrick) {
  const auto [lo, hi] = value_range(read_volume(kNucleon).view());
  const std::string range = "the samples range from " + std::to_string(static_cast<int>(lo)) +
                            " to " + std::to_string(static_cast<int>(hi));
  IsosurfaceParams p = nucleon();
  p.iso = 1000;
  EXPECT_EQ(message_of(p), "no surface at isovalue 1000 in " + kNucleon + ": " + range +
                               ", all below it; set the isovalue inside the range, or to nan "
                               "for the automatic isovalue");
  p.memory = "256KiB";
  EXPECT_NE(message_of(p).find(range + ", all below it"), std::string::npos) << message_of(p);
  p.memory = "0";
  p.iso = -1;
  EXPECT_NE(message_of(p).find(range + ", all at or above it"), std::string::npos) << message_of(p);
  // Samples on both sides, yet no face (Dual Contouring's border cells, a volume one sample
  // thick): moving the isovalue into the range is no advice.
  const std::filesystem::path thin = dir_ / "thin_4x4x1_uint8.raw";
  std::ofstream(thin, std::ios::binary) << std::string(8, '\0') << std::string(8, '\xff');
  p.file = thin.string();
  p.iso = 100;
  const std::string m = message_of(p);
  EXPECT_NE(m.find("but no face crosses it"), std::string::npos) << m;
  EXPECT_NE(m.find("; choose another isovalue (nan: automatic) or method"), std::string::npos) << m;
}

TEST_F(MeshlabJob, BricksAndSimplification) {
  IsosurfaceParams p = nucleon();
  const IsosurfaceResult whole = run_isosurface(p, "", {});
  p.memory = "256KiB";
  const IsosurfaceResult bricked = run_isosurface(p, dir_.string(), {});
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.mesh.triangles, whole.mesh.triangles);
  EXPECT_EQ(bricked.mesh.positions, whole.mesh.positions);
  // No intermediate file left.
  EXPECT_TRUE(std::filesystem::is_empty(dir_));
  p.memory = "0";
  p.simplify = 0.2;
  const IsosurfaceResult simplified = run_isosurface(p, "", {});
  EXPECT_EQ(simplified.triangles_extracted, whole.mesh.triangles.size());
  EXPECT_NEAR(static_cast<double>(simplified.mesh.triangles.size()),
              0.2 * whole.mesh.triangles.size(), 0.02 * 0.2 * whole.mesh.triangles.size());
}

// The layer is the mesh `isotile extract` writes for the same settings: the fields go through
// the CLI's pipeline, simplification included, in core and brick by brick; the progress of a
// bricked run only moves forward too.
TEST_F(MeshlabJob, GivesTheCliPipelinesMeshForTheSameSettings) {
  const std::filesystem::path& temp = dir_;
  for (const std::string memory : {"0", "512KiB"}) {
    IsosurfaceParams p = nucleon();
    p.method = 1;
    p.simplify = 0.3;
    p.normals = true;
    p.memory = memory;
    double last = -1, seams_from = 2, seams_to = -1;
    bool ordered = true;
    const IsosurfaceResult job =
        run_isosurface(p, temp.string(), [&](const std::string& stage, double fraction) {
          ordered = ordered && fraction >= last && fraction <= 1;
          last = fraction;
          if (stage == "simplifying the bricks' seams") {
            seams_from = std::min(seams_from, fraction);
            seams_to = std::max(seams_to, fraction);
          }
        });
    EXPECT_TRUE(ordered) << memory;
    // Brick by brick the seams' pass has a label and a share of the bar of its own (it showed
    // "simplifying" with the bar held at the bricks' end).
    if (memory != "0") {
      EXPECT_GE(seams_from, 0.85) << memory;
      EXPECT_GT(seams_to, seams_from) << memory;
      EXPECT_LE(seams_to, 0.9) << memory;
    } else {
      EXPECT_EQ(seams_to, -1) << memory;
    }
    // `isotile extract NUCLEON --iso 60.5 --method macet --normals --simplify 0.3
    // [--memory 512KiB] -o cli.ply`, as tiler/cli/extract_command.cpp builds it.
    PipelineInput in;
    in.path = kNucleon;
    PipelineOptions o;
    o.iso = 60.5;
    o.extract.method = Method::Macet;
    o.extract.normals = true;
    o.simplify = 0.3;
    if (memory != "0") o.memory = memory;
    o.output = (temp / "cli.ply").string();
    o.keep_mesh = false;
    const PipelineResult cli_run = run_pipeline(in, o);
    const Mesh cli = read_mesh(temp / "cli.ply");
    ASSERT_LT(cli.triangles.size(), cli_run.triangles_extracted) << memory;  // simplified
    EXPECT_EQ(job.mesh.positions, cli.positions) << memory;
    EXPECT_EQ(job.mesh.triangles, cli.triangles) << memory;
    EXPECT_EQ(job.mesh.normals, cli.normals) << memory;
    EXPECT_FALSE(job.mesh.normals.empty()) << memory;
    EXPECT_EQ(job.triangles_extracted, cli_run.triangles_extracted) << memory;
    EXPECT_EQ(job.bricks, cli_run.bricks) << memory;
    EXPECT_EQ(job.bricks > 1, memory != "0") << memory;
    std::filesystem::remove(temp / "cli.ply");
  }
  // Nothing of the bricked run left beside.
  EXPECT_TRUE(std::filesystem::is_empty(temp));
}

TEST_F(MeshlabJob, IsoAutoIsTheLibrarysRuleInCoreAndBrickByBrick) {
  IsosurfaceParams p = nucleon();
  p.iso = std::nan("");  // ignored
  p.iso_auto = true;
  const IsosurfaceResult whole = run_isosurface(p, "", {});
  const Volume v = read_volume(kNucleon, {});
  EXPECT_EQ(whole.iso, otsu_isovalue(value_histogram(v.view())));
  EXPECT_GT(whole.mesh.triangles.size(), 1000u);
  EXPECT_NE(whole.layer_name.find(" mc "), std::string::npos) << whole.layer_name;
  ASSERT_TRUE(whole.range.has_value());
  EXPECT_EQ(*whole.range, value_range(v.view()));
  p.memory = "256KiB";
  const IsosurfaceResult bricked = run_isosurface(p, dir_.string(), {});
  EXPECT_TRUE(std::filesystem::is_empty(dir_));  // the private folder went with its file
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.iso, whole.iso);
  EXPECT_EQ(bricked.range, whole.range);
  EXPECT_EQ(bricked.mesh.triangles, whole.mesh.triangles);
}

TEST_F(MeshlabJob, TheBrickFileLivesInAPrivateFolder) {
  // A link another user could plant in the shared temporary folder, at the names the filter
  // once wrote (isotile-meshlab-PID-N.ply): never written through.
  const std::filesystem::path& dir = dir_;
  const std::filesystem::path victim = dir / "victim.txt";
  { std::ofstream(victim) << "keep"; }
  for (int n = 0; n < 4; ++n)
    std::filesystem::create_symlink(victim, dir / ("isotile-meshlab-" + std::to_string(::getpid()) +
                                                   "-" + std::to_string(n) + ".ply"));
  IsosurfaceParams p = nucleon();
  p.memory = "256KiB";
  const IsosurfaceResult r = run_isosurface(p, dir.string(), {});
  EXPECT_GT(r.mesh.triangles.size(), 1000u);
  std::ifstream in(victim);
  std::string text;
  in >> text;
  EXPECT_EQ(text, "keep");
  // Nothing of the run is left: the private folder went with its file.
  int entries = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    (void)e;
    ++entries;
  }
  EXPECT_EQ(entries, 5);
  // No temporary folder (TMPDIR names one that does not exist; Qt then gives none): said so,
  // where the standard library's filesystem_error named neither.
  const char* was = std::getenv("TMPDIR");
  const std::string before = was ? was : "";
  ::setenv("TMPDIR", (dir / "gone").c_str(), 1);
  const std::string m = message_of(p);
  if (was)
    ::setenv("TMPDIR", before.c_str(), 1);
  else
    ::unsetenv("TMPDIR");
  EXPECT_NE(m.find("no temporary folder for the bricks' mesh (TMPDIR is '" +
                   (dir / "gone").string() + "')"),
            std::string::npos)
      << m;
}

TEST_F(MeshlabJob, BadFieldsSayWhatIsWrong) {
  struct Case {
    void (*edit)(IsosurfaceParams&);
    const char* says;
  } cases[] = {
      {[](IsosurfaceParams& p) { p.file = ""; }, "'file' field is empty"},
      {[](IsosurfaceParams& p) { p.file = "/nonexistent/v_8x8x8_uint8.raw"; }, "no such file"},
      {[](IsosurfaceParams& p) { p.file = ISOTILE_TEST_DATA; }, "no DICOM series found"},
      {[](IsosurfaceParams& p) { p.dims = "41,x,41"; }, "'Raw dims' must be three"},
      {[](IsosurfaceParams& p) { p.type = "uint12"; }, "unknown 'Raw type' 'uint12'"},
      {[](IsosurfaceParams& p) { p.endian = "middle"; }, "'Raw byte order' must be"},
      {[](IsosurfaceParams& p) { p.spacing = "1,1"; }, "'Spacing' must be three"},
      {[](IsosurfaceParams& p) { p.series = "1.2.840"; }, "'DICOM series' applies to DICOM only"},
      {[](IsosurfaceParams& p) { p.method = 3; }, "'Method' must be one of 0 Marching Cubes"},
      {[](IsosurfaceParams& p) { p.backend = -1; }, "'Backend' must be one of"},
      {[](IsosurfaceParams& p) {
         p.method = 2;
         p.dc_vertices = 2;
       },
       "'DC vertices' must be one of 0 patch, 1 cell"},
      {[](IsosurfaceParams& p) {
         p.method = 1;
         p.macet_relax = 0.7;
       },
       "'Macet relax' must be in [0, 0.5), got 0.7"},
      {[](IsosurfaceParams& p) { p.simplify = -1e-9; },
       "'Simplify' must be in (0, 1] (1: off), got -1e-09"},
      {[](IsosurfaceParams& p) { p.memory = "much"; }, "much"},
      {[](IsosurfaceParams& p) { p.simplify = 1.5; }, "'Simplify' must be in (0, 1]"},
      {[](IsosurfaceParams& p) { p.iso = INFINITY; }, "'Isovalue' must be a finite number"},
  };
  for (const Case& c : cases) {
    IsosurfaceParams p = nucleon();
    c.edit(p);
    const std::string m = message_of(p);
    EXPECT_NE(m.find(c.says), std::string::npos) << "wanted '" << c.says << "', got: " << m;
  }
  // Raw fields on a file that is not raw: the dialog's labels, the byte order's too.
  IsosurfaceParams p = nucleon();
  p.file = "field:sphere:8";
  p.endian = "big";
  const std::string m = message_of(p);
  EXPECT_NE(m.find("'Raw byte order' big apply only to raw files"), std::string::npos) << m;
}

// The dialog shows every method's fields and keeps their last values: another method's fields
// away from their defaults are left out (and named for the log), the mesh the chosen method's.
TEST_F(MeshlabJob, AnotherMethodsFieldsAreLeftOutAndNamed) {
  const IsosurfaceResult plain = run_isosurface(nucleon(), "", {});
  EXPECT_TRUE(plain.unused_fields.empty());
  IsosurfaceParams p = nucleon();
  p.macet_quality = 1;
  p.macet_relax = 0.2;
  p.dc_solver = 2;
  p.dc_hermite = 1;
  p.dc_vertices = 1;
  const IsosurfaceResult mc = run_isosurface(p, "", {});
  EXPECT_EQ(mc.unused_fields, (std::vector<std::string>{"Macet quality", "Macet relax", "DC solver",
                                                        "DC Hermite", "DC vertices"}));
  EXPECT_EQ(mc.mesh.positions, plain.mesh.positions);
  EXPECT_EQ(mc.mesh.triangles, plain.mesh.triangles);
  p.method = 2;
  const IsosurfaceResult dc = run_isosurface(p, "", {});
  EXPECT_EQ(dc.unused_fields, (std::vector<std::string>{"Macet quality", "Macet relax"}));
  IsosurfaceParams q = nucleon();
  q.method = 2;
  q.dc_solver = 2;
  q.dc_hermite = 1;
  q.dc_vertices = 1;
  const IsosurfaceResult dc_only = run_isosurface(q, "", {});
  EXPECT_TRUE(dc_only.unused_fields.empty());
  EXPECT_EQ(dc.mesh.positions, dc_only.mesh.positions);
  EXPECT_EQ(dc.mesh.triangles, dc_only.mesh.triangles);
}

// Library messages name the dialog's fields, not the CLI's options.
TEST_F(MeshlabJob, MessagesNameTheDialogsFields) {
  EXPECT_EQ(in_dialog_terms("--quality applies to --method macet only"),
            "'Macet quality' applies to Method Macet only");
  EXPECT_EQ(in_dialog_terms("pass --dims X,Y,Z and --type T; --iso auto or --iso 3"),
            "pass 'Raw dims' and 'Raw type'; 'Isovalue' nan or 'Isovalue' 3");
  EXPECT_EQ(in_dialog_terms("--dims-x, --ascii"), "--dims-x, --ascii");
  // Not in a path, nor in a command quoted for the shell.
  EXPECT_EQ(in_dialog_terms("/d/--type/v.raw: bad; `isotile info v.raw --iso 3`"),
            "/d/--type/v.raw: bad; `isotile info v.raw --iso 3`");
  IsosurfaceParams p = nucleon();
  p.series = "1.2.3";
  const std::string m = message_of(p);
  EXPECT_NE(m.find("'DICOM series' applies to DICOM only"), std::string::npos) << m;
  EXPECT_EQ(m.find("--"), std::string::npos) << m;
}

TEST_F(MeshlabJob, SimplifyFilterTargets) {
  const IsosurfaceResult r = run_isosurface(nucleon(), "", {});
  const std::size_t n = r.mesh.triangles.size();
  SimplifyStats st;
  const Mesh ratio = run_simplify(r.mesh, {.ratio = 0.3}, &st);
  EXPECT_NEAR(static_cast<double>(ratio.triangles.size()), 0.3 * n, 0.02 * 0.3 * n);
  EXPECT_EQ(st.faces_before, n);
  const Mesh faces = run_simplify(r.mesh, {.ratio = 0.9, .faces = 500}, nullptr);
  EXPECT_NEAR(static_cast<double>(faces.triangles.size()), 500, 10);
  EXPECT_EQ(mesh_topology(faces).euler, mesh_topology(r.mesh).euler);
  // The library's refusals in the dialog's labels.
  for (const auto& [params, says] : std::vector<std::pair<SimplifyParams, std::string>>{
           {{.ratio = 0}, "give 'Faces kept (fraction)', 'Faces kept (count)' or 'Maximum error'"},
           {{.ratio = 1.5}, "'Faces kept (fraction)' must be in (0, 1], got 1.5"},
           {{.ratio = 0.5, .min_quality = 2}, "'Quality floor' must be in [0, 1]"}}) {
    try {
      run_simplify(r.mesh, params, nullptr);
      ADD_FAILURE() << says;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), says);
    }
  }
}

// A file of a DICOM series reads the series; the mesh comes in its world frame, in core and in
// bricks alike.
TEST_F(MeshlabJob, DicomFileGivesTheSeriesInWorldCoordinates) {
  const std::filesystem::path file =
      std::filesystem::path(ISOTILE_SHARED_DATA) / "dicom_uih_t1_head_slab/00000060.dcm";
  if (!std::filesystem::exists(file)) ISOTILE_SKIP(SharedData, "no shared data at " << file);
  if (!itk_available()) ISOTILE_SKIP(Itk, "built without ITK");
  IsosurfaceParams p;
  p.file = file.string();
  p.iso = 300;
  const Volume v = read_volume(p.file);
  ExtractOptions o;
  o.iso = 300;
  Mesh expected = extract(v.view(), o);
  apply_frame(mesh_frame(v.view()), expected);
  ASSERT_GT(expected.triangles.size(), 1000u);
  const IsosurfaceResult whole = run_isosurface(p, "", {});
  // The layer is named after the series' description, which the log gives with its UID.
  const VolumeHeader h = read_volume_header(p.file);
  ASSERT_FALSE(h.series_description.empty());
  EXPECT_EQ(whole.layer_name, layer_name("", h.series_description, "mc", 300));
  EXPECT_NE(
      whole.description.find("DICOM series '" + h.series_description + "' (" + h.series_uid + ")"),
      std::string::npos)
      << whole.description;
  EXPECT_EQ(whole.mesh.positions, expected.positions);
  EXPECT_EQ(whole.mesh.triangles, expected.triangles);
  // The series cannot be read by region: a budget below the whole volume (35 MiB) is refused.
  p.memory = "16MiB";
  EXPECT_NE(message_of(p).find("does not fit 'Memory'"), std::string::npos) << message_of(p);
  p.memory = "64MiB";
  const IsosurfaceResult bricked = run_isosurface(p, dir_.string(), {});
  EXPECT_TRUE(std::filesystem::is_empty(dir_));
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.mesh.positions, expected.positions);
  p.memory = "";
  p.series = "1.2.3";
  EXPECT_NE(message_of(p).find("no DICOM series with UID 1.2.3"), std::string::npos);
}

// A DICOM series without a SeriesDescription is named after its folder, whichever slice was
// chosen (it was named after the slice: two names for one series), and the log says so.
TEST_F(MeshlabJob, ASeriesWithoutADescriptionIsNamedAfterItsFolder) {
  const std::filesystem::path series =
      std::filesystem::path(ISOTILE_SHARED_DATA) / "dicom_uih_t1_head_slab";
  if (!std::filesystem::exists(series)) ISOTILE_SKIP(SharedData, "no shared data at " << series);
  if (!itk_available()) ISOTILE_SKIP(Itk, "built without ITK");
  const std::filesystem::path folder = dir_ / "head scan";
  std::filesystem::create_directory(folder);
  for (const char* name : {"00000060.dcm", "00000061.dcm", "00000062.dcm", "00000063.dcm"}) {
    std::string bytes = slurp(series / name);
    // SeriesDescription (0008,103E), LO: its value blanked, its length kept.
    const std::size_t tag = bytes.find(std::string("\x08\x00\x3e\x10LO", 6));
    ASSERT_NE(tag, std::string::npos) << name;
    const std::size_t length = static_cast<unsigned char>(bytes[tag + 6]) |
                               static_cast<std::size_t>(static_cast<unsigned char>(bytes[tag + 7]))
                                   << 8;
    bytes.replace(tag + 8, length, std::string(length, ' '));
    std::ofstream(folder / name, std::ios::binary) << bytes;
  }
  for (const char* name : {"00000060.dcm", "00000063.dcm"}) {
    IsosurfaceParams p;
    p.file = (folder / name).string();
    p.iso = 300;
    const IsosurfaceResult r = run_isosurface(p, "", {});
    EXPECT_EQ(r.layer_name, "head scan mc iso300") << name;
    EXPECT_NE(r.description.find("DICOM series without a description ("), std::string::npos)
        << r.description;
  }
}

}  // namespace
}  // namespace isotile::meshlab
