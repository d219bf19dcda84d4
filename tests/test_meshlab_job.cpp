// The MeshLab filters' Qt-free part: fields to library calls, and the messages a MeshLab user
// sees for bad fields (runs in every build, sanitizers included).
#include "meshlab_plugin/isosurface_job.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_topology.h"
#include "core/volume/itk_reader.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/volume_io.h"
#include "skip_support.h"

namespace isotile::meshlab {
namespace {

const std::string kNucleon = std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz";

IsosurfaceParams nucleon() {
  IsosurfaceParams p;
  p.file = kNucleon;
  p.iso = 60.5;
  return p;
}

std::string message_of(const IsosurfaceParams& p) {
  try {
    run_isosurface(p, "", {});
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(MeshlabJob, ExtractsNamesTheLayerAndReportsProgress) {
  IsosurfaceParams p = nucleon();
  p.method = 1;
  int last = -1;
  bool ordered = true;
  const IsosurfaceResult r = run_isosurface(p, "", [&](int percent, const std::string&) {
    ordered = ordered && percent >= last;
    last = percent;
  });
  EXPECT_TRUE(ordered);
  EXPECT_GT(last, 50);
  EXPECT_GT(r.mesh.triangles.size(), 1000u);
  EXPECT_EQ(r.layer_name, "nucleon_41x41x41_uint8.raw.gz macet 60.5");
  EXPECT_EQ(r.backend, "cpu");
  EXPECT_EQ(r.bricks, 1);
  EXPECT_GT(r.quality.mean, 0.8);
  EXPECT_EQ(r.quality.triangles, r.mesh.triangles.size());
}

TEST(MeshlabJob, BricksAndSimplification) {
  IsosurfaceParams p = nucleon();
  const IsosurfaceResult whole = run_isosurface(p, "", {});
  p.memory = "256KiB";
  const IsosurfaceResult bricked = run_isosurface(p, ::testing::TempDir(), {});
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.mesh.triangles, whole.mesh.triangles);
  EXPECT_EQ(bricked.mesh.positions, whole.mesh.positions);
  p.memory = "0";
  p.simplify = 0.2;
  const IsosurfaceResult simplified = run_isosurface(p, "", {});
  EXPECT_EQ(simplified.triangles_extracted, whole.mesh.triangles.size());
  EXPECT_NEAR(static_cast<double>(simplified.mesh.triangles.size()),
              0.2 * whole.mesh.triangles.size(), 0.02 * 0.2 * whole.mesh.triangles.size());
  // No intermediate file left in the temporary folder.
  for (const auto& e : std::filesystem::directory_iterator(::testing::TempDir()))
    EXPECT_EQ(e.path().filename().string().rfind("isotile-meshlab-", 0), std::string::npos)
        << e.path();
}

TEST(MeshlabJob, IsoAutoIsTheLibrarysRuleInCoreAndBrickByBrick) {
  IsosurfaceParams p = nucleon();
  p.iso = std::nan("");  // ignored
  p.iso_auto = true;
  const IsosurfaceResult whole = run_isosurface(p, "", {});
  const Volume v = read_volume(kNucleon, {});
  EXPECT_EQ(whole.iso, otsu_isovalue(value_histogram(v.view())));
  EXPECT_GT(whole.mesh.triangles.size(), 1000u);
  EXPECT_NE(whole.layer_name.find(" mc "), std::string::npos) << whole.layer_name;
  p.memory = "256KiB";
  const IsosurfaceResult bricked = run_isosurface(p, ::testing::TempDir(), {});
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.iso, whole.iso);
  EXPECT_EQ(bricked.mesh.triangles, whole.mesh.triangles);
}

TEST(MeshlabJob, TheBrickFileLivesInAPrivateFolder) {
  // A link another user could plant in the shared temporary folder, at the names the filter
  // once wrote (isotile-meshlab-PID-N.ply): never written through.
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / ("isotile-job-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
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
  std::filesystem::remove_all(dir);
}

TEST(MeshlabJob, BadFieldsSayWhatIsWrong) {
  struct Case {
    void (*edit)(IsosurfaceParams&);
    const char* says;
  } cases[] = {
      {[](IsosurfaceParams& p) { p.file = ""; }, "'file' field is empty"},
      {[](IsosurfaceParams& p) { p.file = "/nonexistent/v_8x8x8_uint8.raw"; }, "no such file"},
      {[](IsosurfaceParams& p) { p.file = ISOTILE_TEST_DATA; }, "no DICOM series found"},
      {[](IsosurfaceParams& p) { p.dims = "41,x,41"; }, "dims must be three"},
      {[](IsosurfaceParams& p) { p.type = "uint12"; }, "unknown type 'uint12'"},
      {[](IsosurfaceParams& p) { p.endian = "middle"; }, "endian must be"},
      {[](IsosurfaceParams& p) { p.spacing = "1,1"; }, "spacing must be three"},
      {[](IsosurfaceParams& p) { p.series = "1.2.840"; }, "series applies to DICOM only"},
      {[](IsosurfaceParams& p) { p.method = 3; }, "method must be one of 0 Marching Cubes"},
      {[](IsosurfaceParams& p) { p.backend = -1; }, "backend must be one of"},
      {[](IsosurfaceParams& p) {
         p.method = 2;
         p.dc_vertices = 2;
       },
       "dc_vertices must be one of 0 patch, 1 cell"},
      {[](IsosurfaceParams& p) { p.macet_relax = 0.2; }, "Macet method only"},
      {[](IsosurfaceParams& p) { p.macet_relax = 0.7; }, "macet_relax must be in [0, 0.5)"},
      {[](IsosurfaceParams& p) { p.memory = "much"; }, "much"},
      {[](IsosurfaceParams& p) { p.simplify = 1.5; }, "simplify is the fraction"},
      {[](IsosurfaceParams& p) { p.iso = INFINITY; }, "iso must be a finite number"},
  };
  for (const Case& c : cases) {
    IsosurfaceParams p = nucleon();
    c.edit(p);
    const std::string m = message_of(p);
    EXPECT_NE(m.find(c.says), std::string::npos) << "wanted '" << c.says << "', got: " << m;
  }
}

TEST(MeshlabJob, SimplifyFilterTargets) {
  const IsosurfaceResult r = run_isosurface(nucleon(), "", {});
  const std::size_t n = r.mesh.triangles.size();
  SimplifyStats st;
  const Mesh ratio = run_simplify(r.mesh, {.ratio = 0.3}, &st);
  EXPECT_NEAR(static_cast<double>(ratio.triangles.size()), 0.3 * n, 0.02 * 0.3 * n);
  EXPECT_EQ(st.faces_before, n);
  const Mesh faces = run_simplify(r.mesh, {.ratio = 0.9, .faces = 500}, nullptr);
  EXPECT_NEAR(static_cast<double>(faces.triangles.size()), 500, 10);
  EXPECT_EQ(mesh_topology(faces).euler, mesh_topology(r.mesh).euler);
  EXPECT_THROW(run_simplify(r.mesh, {.ratio = 0}, nullptr), InputError);
}

// A file of a DICOM series reads the series; the mesh comes in its world frame, in core and in
// bricks alike.
TEST(MeshlabJob, DicomFileGivesTheSeriesInWorldCoordinates) {
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
  EXPECT_EQ(whole.mesh.positions, expected.positions);
  EXPECT_EQ(whole.mesh.triangles, expected.triangles);
  // The series cannot be read by region: a budget below the whole volume (35 MiB) is refused.
  p.memory = "16MiB";
  EXPECT_NE(message_of(p).find("does not fit --memory"), std::string::npos);
  p.memory = "64MiB";
  const IsosurfaceResult bricked = run_isosurface(p, ::testing::TempDir(), {});
  EXPECT_GT(bricked.bricks, 1);
  EXPECT_EQ(bricked.mesh.positions, expected.positions);
  p.memory = "";
  p.series = "1.2.3";
  EXPECT_NE(message_of(p).find("no DICOM series with UID 1.2.3"), std::string::npos);
}

}  // namespace
}  // namespace isotile::meshlab
