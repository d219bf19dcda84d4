// `isotile simplify`, `extract --simplify` and `quality --reference` as scripts use them: the
// stats keys, exit codes and one-line errors, and no output left behind by a failure.
#include <gtest/gtest.h>

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>

#include "cli_support.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_topology.h"

namespace {

using Result = isotile::testing::CliResult;
using isotile::testing::slurp;

class CliSimplify : public isotile::testing::CliTest {};

TEST_F(CliSimplify, SimplifyWritesTheMeshAndItsStats) {
  ASSERT_EQ(run("extract field:torus:48 --method macet -q -o t.ply").code, 0);
  const Result r = run("simplify t.ply s.ply --ratio 0.2 --stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  for (const char* key :
       {"triangles", "vertices", "triangles_before", "radius_ratio_min", "radius_ratio_mean",
        "radius_ratio_q001", "radius_ratio_q01", "boundary_edges", "nonmanifold_edges", "euler",
        "watertight", "simplify_hausdorff_mean", "simplify_hausdorff_max", "seconds",
        "peak_rss_mb"})
    EXPECT_TRUE(j.contains(key)) << key;
  for (const char* key : {"read", "simplify", "write", "total"})
    EXPECT_TRUE(j["seconds"].contains(key)) << key;
  const isotile::Mesh in = isotile::read_mesh(dir_ / "t.ply");
  const isotile::Mesh out = isotile::read_mesh(dir_ / "s.ply");
  EXPECT_EQ(j["triangles_before"].get<std::size_t>(), in.triangles.size());
  EXPECT_EQ(j["triangles"].get<std::size_t>(), out.triangles.size());
  EXPECT_NEAR(j["triangles"].get<double>(), 0.2 * in.triangles.size(),
              0.02 * 0.2 * in.triangles.size());
  EXPECT_EQ(j["euler"], 0);
  EXPECT_EQ(j["closed"], true);
  EXPECT_GT(j["simplify_hausdorff_max"].get<double>(), 0.0);
  EXPECT_LT(j["simplify_hausdorff_max"].get<double>(), 1.0);
  EXPECT_GE(j["radius_ratio_min"].get<double>(), 0.2);
}

TEST_F(CliSimplify, FacesAndMaxErrorTargets) {
  ASSERT_EQ(run("extract field:sphere:40 -q -o s.ply").code, 0);
  Result r = run("simplify s.ply f.obj --faces 500 --stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NEAR(nlohmann::json::parse(r.out)["triangles"].get<double>(), 500, 10);
  r = run("simplify s.ply e.off --max-error 0.3 --stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_LE(j["simplify_hausdorff_max"].get<double>(), 0.3);
  EXPECT_LT(j["triangles"].get<double>(), j["triangles_before"].get<double>() / 2);
}

// A result well above its target is said (it was not: 5,238 faces for 3,850 on the gyroid 64's
// Marching Cubes mesh, whose long border and thin parts hold faces), in core and out of core;
// one on target is not.
TEST_F(CliSimplify, ATargetMissedByMoreThanATenthIsAWarning) {
  ASSERT_EQ(run("extract field:gyroid:64 -q -o g.ply").code, 0);
  Result r = run("simplify g.ply s.ply --ratio 0.05 --stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const auto got = j["triangles"].get<std::uint64_t>();
  ASSERT_GT(got, 3850u * 11 / 10);
  EXPECT_NE(r.err.find("isotile: warning: simplification stopped at " + std::to_string(got) +
                       " triangles, "),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("above its target of 3850"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  r = run("simplify g.ply s.ply --ratio 0.1 -q");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  r = run("extract field:gyroid:64 --simplify 0.1 --memory 1MiB -q -o t.ply");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("above its target of 7700"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("larger bricks, a larger --memory"), std::string::npos) << r.err;
}

// Well below its target (a raised --min-quality: the cleanup collapses triangles below the floor
// after the count is reached) is said too; it was not (8,100 faces for 9,338).
TEST_F(CliSimplify, ATargetUndershotByMoreThanATenthIsAWarning) {
  ASSERT_EQ(run("extract field:gyroid:32 -q -o g.ply").code, 0);
  Result r = run("simplify g.ply s.ply --ratio 0.5 --min-quality 1 --no-relax --stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const auto got = j["triangles"].get<std::uint64_t>();
  const auto target = j["simplify_target_faces"].get<std::uint64_t>();
  ASSERT_LT(got, target * 9 / 10);
  EXPECT_EQ(r.err, "isotile: warning: simplification ended at " + std::to_string(got) +
                       " triangles, " +
                       std::to_string(std::lround(100.0 * double(target - got) / double(target))) +
                       "% below its target of " + std::to_string(target) +
                       ": the cleanup collapsed triangles below the quality floor (--min-quality) "
                       "after the target was reached\n");
  r = run("simplify g.ply s.ply --ratio 0.5 -q");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
}

TEST_F(CliSimplify, BadArgumentsFailWithOneLineAndNoOutput) {
  ASSERT_EQ(run("extract field:sphere:20 -q -o s.ply").code, 0);
  struct Case {
    const char* args;
    int code;
    const char* says;
  };
  for (const Case& c : {
           Case{"simplify s.ply o.ply", 2, "give one of --ratio, --faces and --max-error"},
           Case{"simplify s.ply o.ply --ratio 0.5 --faces 10", 2, "excludes"},
           // Values out of range are usage errors naming the option (a bad value used to read
           // as a missing one, and --faces -1 wrapped to 2^64 - 1: nothing done, exit 0).
           Case{"simplify s.ply o.ply --ratio 1.5", 2, "--ratio: must be a number in (0, 1]"},
           Case{"simplify s.ply o.ply --ratio 0", 2, "--ratio: must be a number in (0, 1]"},
           Case{"simplify s.ply o.ply --ratio nan", 2, "--ratio: must be a number in (0, 1]"},
           Case{"simplify s.ply o.ply --max-error -1", 2, "--max-error: must be a distance above"},
           Case{"simplify s.ply o.ply --faces -1", 2, "--faces: must be a whole number of faces"},
           Case{"simplify s.ply o.ply --faces 99999999999999999999", 2, "--faces: must be"},
           Case{"simplify s.ply o.ply --faces 2.5", 2, "--faces: must be a whole number"},
           Case{"simplify missing.ply o.ply --ratio 0.5", 1, "missing.ply"},
           Case{"simplify s.ply o.xyz --ratio 0.5", 1, ".xyz"},
           Case{"simplify s.ply --ratio 0.5", 2, "OUT"},
           Case{"extract field:sphere:20 -o o.ply --simplify 0", 2, "simplify"},
           Case{"extract field:sphere:20 -o o.ply --simplify 2", 2, "simplify"},
           // Not a number: its check once converted it itself and ended the program.
           Case{"extract field:sphere:20 -o o.ply --simplify abc", 2,
                "--simplify: must be a number in (0, 1], got 'abc'"},
           Case{"extract field:sphere:20 -o o.ply --simplify 1e400", 2, "--simplify: must be"},
           Case{"extract field:sphere:20 -o o.ply --method dc --quads --simplify 0.5", 1,
                "drop --quads"},
       }) {
    const Result r = run(std::string(c.args) + " -q");
    EXPECT_EQ(r.code, c.code) << c.args << ": " << r.err;
    EXPECT_NE(r.err.find(c.says), std::string::npos) << c.args << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir_ / "o.ply")) << c.args;
  }
  EXPECT_EQ(stray_files({"s.ply"}), std::vector<std::string>{});
}

// A mesh without a face of non-zero area has no surface distance: --stats says null and the run
// succeeds, as without --stats (it exited 1 after writing the output).
TEST_F(CliSimplify, StatsOfAMeshWithoutAreaSayNull) {
  std::ofstream(dir_ / "flat.obj") << "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n";
  const Result r = run("simplify flat.obj o.ply --ratio 0.5 --stats s.json -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(slurp(dir_ / "s.json"));
  for (const char* key : {"simplify_hausdorff_mean", "simplify_hausdorff_max",
                          "simplify_hausdorff_max_at", "simplify_hausdorff_max_direction"})
    EXPECT_TRUE(j.contains(key) && j[key].is_null()) << key;
}

TEST_F(CliSimplify, ExtractSimplifyReportsBothMeshesInVoxels) {
  // Spacing 2 along z: the distances in the stats are in voxels, the mesh in world units.
  const std::string nucleon = std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz";
  const Result r = run("extract " + nucleon +
                       " --iso 60.5 --method macet --spacing 1,1,2 --simplify 0.1 -o g.ply "
                       "--stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["simplify"], 0.1);
  const double before = j["triangles_before"].get<double>();
  EXPECT_NEAR(j["triangles"].get<double>(), 0.1 * before, 0.02 * 0.1 * before);
  EXPECT_EQ(j["watertight"], true);
  EXPECT_EQ(j["nonmanifold_edges"], 0);
  EXPECT_TRUE(j["seconds"].contains("simplify"));
  EXPECT_LT(j["simplify_hausdorff_max"].get<double>(), 1.5);
  EXPECT_GT(j["simplify_hausdorff_mean"].get<double>(), 0.0);
  const isotile::Mesh m = isotile::read_mesh(dir_ / "g.ply");
  EXPECT_EQ(m.triangles.size(), j["triangles"].get<std::size_t>());
  float zmax = 0;
  for (const auto& p : m.positions) zmax = std::max(zmax, p[2]);
  EXPECT_GT(zmax, 41.0f);  // world units: past the 41 voxels along z
}

TEST_F(CliSimplify, OutOfCoreReportsItsBrickPlan) {
  const Result r = run(
      "extract field:torus:64 --method macet --memory 2MiB --simplify 0.1 -o t.ply --stats - -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["simplify"], 0.1);
  EXPECT_GT(j["bricks"].get<int>(), 1);
  ASSERT_TRUE(j.contains("simplify_brick_plan"));
  EXPECT_EQ(j["simplify_brick_plan"]["brick_grid"], j["brick_grid"]);
  EXPECT_EQ(j["simplify_brick_plan"]["seam_grid"].size(), 3u);
  const auto& grid = j["simplify_brick_plan"]["seam_grid"];
  EXPECT_GE(j["simplify_brick_plan"]["seam_parts"].get<int>(),
            grid[0].get<int>() * grid[1].get<int>() * grid[2].get<int>());
  const double before = j["triangles_before"].get<double>();
  EXPECT_NEAR(j["triangles"].get<double>(), 0.1 * before, 0.02 * 0.1 * before);
  EXPECT_TRUE(j["simplify_hausdorff_max"].is_null());
  EXPECT_TRUE(j["seconds"].contains("seams"));
  // The simplifying tiler does not time the extracting tiler's stages: no zeros posing as times.
  EXPECT_FALSE(j["seconds"].contains("stages"));
  const isotile::Mesh m = isotile::read_mesh(dir_ / "t.ply");
  EXPECT_EQ(m.triangles.size(), j["triangles"].get<std::size_t>());
  EXPECT_TRUE(isotile::mesh_topology(m).closed);
  // The budget is part of the plan: another budget, another (valid) result.
  ASSERT_EQ(
      run("extract field:torus:64 --method macet --memory 64MiB --simplify 0.1 -o u.ply -q").code,
      0);
  EXPECT_TRUE(isotile::mesh_topology(isotile::read_mesh(dir_ / "u.ply")).closed);
  EXPECT_EQ(stray_files({"t.ply", "u.ply"}), std::vector<std::string>{});
}

// A budget too small to simplify brick by brick names the budget that runs: below even the
// extraction's need it named that need (115519 bytes on the nucleon), and a run given it was
// refused again with the simplification's (284719).
TEST_F(CliSimplify, ABudgetTooSmallNamesOneThatRuns) {
  const std::string run_at = "extract " + std::string(ISOTILE_TEST_DATA) +
                             "/nucleon_41x41x41_uint8.raw.gz --iso 49.5 --simplify 0.25 -o s.ply "
                             "-q --memory ";
  std::string named;
  for (const std::string budget : {"64KiB", "200000"}) {
    const Result r = run(run_at + budget);
    EXPECT_EQ(r.code, 1) << r.err;
    const std::string needs = "needs ";
    const std::size_t at = r.err.find(needs);
    ASSERT_NE(at, std::string::npos) << r.err;
    const std::string figure = std::to_string(std::stoull(r.err.substr(at + needs.size())));
    if (!named.empty()) EXPECT_EQ(figure, named) << r.err;
    named = figure;
  }
  const Result r = run(run_at + named);
  EXPECT_EQ(r.code, 0) << "--memory " << named << ": " << r.err;
  const std::string one_less = std::to_string(std::stoull(named) - 1);
  EXPECT_EQ(run(run_at + one_less).code, 1);
}

TEST_F(CliSimplify, QualityMeasuresTheDistanceToAReference) {
  ASSERT_EQ(run("extract field:sphere:40 -q -o a.ply").code, 0);
  ASSERT_EQ(run("simplify a.ply b.ply --ratio 0.1 -q").code, 0);
  Result r = run("quality b.ply --reference a.ply --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_GT(j["hausdorff_max"].get<double>(), 0.0);
  EXPECT_GE(j["hausdorff_max"].get<double>(), j["hausdorff_mean"].get<double>());
  EXPECT_EQ(j["hausdorff_reference_to_mesh"]["samples"].get<std::uint64_t>(),
            isotile::read_mesh(dir_ / "a.ply").positions.size() + 200000);
  r = run("quality a.ply --reference a.ply --json");
  EXPECT_LT(nlohmann::json::parse(r.out)["hausdorff_max"].get<double>(), 1e-9);
  r = run("quality a.ply --reference nothere.ply");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("nothere.ply"), std::string::npos);
}

}  // namespace
