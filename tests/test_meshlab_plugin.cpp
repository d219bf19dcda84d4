// The MeshLab plugin in the real meshlabserver (Debian's MeshLab 2020.09) under xvfb-run, driven
// by .mlx scripts made from the shipped example (meshlab_plugin/examples/isosurface.mlx), so that
// a parameter missing from the example fails here. The plugin loads from a private copy of
// MeshLab's layout in the test's folder: nothing on the system changes.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;

struct ServerRun {
  int code = -1;
  std::string log;
};

class MeshlabServer : public isotile::testing::TempDirTest {
 protected:
  MeshlabServer() : TempDirTest("isotile-meshlab-") {}
  void SetUp() override {
#ifdef ISOTILE_SANITIZED
    ISOTILE_SKIP(Meshlab,
                 "a sanitizer-instrumented plugin cannot load into Debian's uninstrumented "
                 "meshlabserver (the sanitizer runtime must come first); the meshlabserver "
                 "tests run in the Release pass");
#endif
    TempDirTest::SetUp();
    // MeshLab looks for plugins next to its real executable only (a symlinked binary does not
    // work): a copy of meshlabserver in bin/, the libraries and plugins it loads beside it.
    const fs::path lib = dir_ / "prefix/lib/x86_64-linux-gnu/meshlab";
    fs::create_directories(dir_ / "prefix/bin");
    fs::create_directories(lib / "plugins");
    fs::copy_file("/usr/bin/meshlabserver", dir_ / "prefix/bin/meshlabserver");
    const fs::path system = "/usr/lib/x86_64-linux-gnu/meshlab";
    fs::create_symlink(system / "libmeshlab-common.so", lib / "libmeshlab-common.so");
    fs::create_symlink(system / "plugins/libio_base.so", lib / "plugins/libio_base.so");
    fs::create_symlink(ISOTILE_MESHLAB_PLUGIN, lib / "plugins/libfilter_isotile.so");
  }
  // The shipped example with some parameters' values replaced.
  static std::string script(const std::map<std::string, std::string>& values) {
    std::string s = slurp(ISOTILE_MESHLAB_EXAMPLE);
    for (const auto& [name, value] : values) {
      const std::string key = "name=\"" + name + "\" value=\"";
      const std::size_t at = s.find(key);
      if (at == std::string::npos) {
        ADD_FAILURE() << "the example has no parameter " << name;
        continue;
      }
      const std::size_t begin = at + key.size();
      s.replace(begin, s.find('"', begin) - begin, value);
    }
    return s;
  }

  // meshlabserver running `mlx` (and writing `output` when given).
  ServerRun run(const std::string& mlx, const std::string& output = "out.ply") {
    std::ofstream(dir_ / "script.mlx") << mlx;
    const std::string cmd = "cd '" + dir_.string() + "' && xvfb-run -a '" +
                            (dir_ / "prefix/bin/meshlabserver").string() + "' -s script.mlx" +
                            (output.empty() ? "" : " -o " + output) + " > log.txt 2>&1";
    const int status = std::system(cmd.c_str());
    ServerRun r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.log = slurp(dir_ / "log.txt");
    return r;
  }

  // `isotile extract ARGS -o cli.ply`.
  isotile::Mesh cli(const std::string& args) {
    const std::string cmd =
        "cd '" + dir_.string() + "' && '" + ISOTILE_CLI + "' -q extract " + args + " -o cli.ply";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    return isotile::read_mesh(dir_ / "cli.ply");
  }

  // The layer MeshLab wrote is the CLI's mesh: same counts, same radius ratios.
  void expect_same_mesh(const isotile::Mesh& layer, const isotile::Mesh& cli,
                        const std::string& what) {
    EXPECT_EQ(layer.triangles.size(), cli.triangles.size()) << what;
    EXPECT_EQ(layer.positions.size(), cli.positions.size()) << what;
    const isotile::QualityStats a = isotile::triangle_quality(layer);
    const isotile::QualityStats b = isotile::triangle_quality(cli);
    EXPECT_NEAR(a.min, b.min, 1e-6) << what;
    EXPECT_NEAR(a.mean, b.mean, 1e-6) << what;
  }
};

// Each method as the filter's enum indices and as the CLI's options.
struct MethodCase {
  const char* method;
  const char* quality;
  const char* dc_vertices;
  const char* cli;
};
constexpr MethodCase kMethods[] = {{"0", "0", "0", "--method mc"},
                                   {"1", "0", "0", "--method macet"},
                                   {"1", "1", "0", "--method macet --quality max"},
                                   {"2", "0", "0", "--method dc"},
                                   {"2", "0", "1", "--method dc --dc-vertices cell"}};

const std::string kNucleon = std::string(ISOTILE_TEST_DATA) + "/nucleon_41x41x41_uint8.raw.gz";

TEST_F(MeshlabServer, EveryMethodGivesTheCliMeshOnASmallVolume) {
  for (const MethodCase& c : kMethods) {
    const ServerRun r = run(script({{"file", kNucleon},
                                    {"iso", "60.5"},
                                    {"method", c.method},
                                    {"macet_quality", c.quality},
                                    {"dc_vertices", c.dc_vertices}}));
    ASSERT_EQ(r.code, 0) << c.cli << "\n" << r.log;
    EXPECT_NE(r.log.find("isotile: "), std::string::npos) << r.log;
    EXPECT_NE(r.log.find("radius ratio min"), std::string::npos) << r.log;
    expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"), cli(kNucleon + " --iso 60.5 " + c.cli),
                     c.cli);
  }
}

TEST_F(MeshlabServer, EngineGivesTheCliMeshForEveryMethod) {
  const fs::path engine = isotile::testing::shared_volume("engine_256x256x128_uint8.raw.gz");
  ISOTILE_REQUIRE_SHARED(engine);
  for (const MethodCase& c : kMethods) {
    const ServerRun r = run(script({{"file", engine.string()},
                                    {"method", c.method},
                                    {"macet_quality", c.quality},
                                    {"dc_vertices", c.dc_vertices}}));
    ASSERT_EQ(r.code, 0) << c.cli << "\n" << r.log;
    expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"),
                     cli(engine.string() + " --iso 49.5 " + c.cli), c.cli);
  }
}

TEST_F(MeshlabServer, TheShippedExampleRuns) {
  const fs::path engine = isotile::testing::shared_volume("engine_256x256x128_uint8.raw.gz");
  // Only `file` changes; without the shared data, the small volume stands in (and its isovalue).
  const bool have = fs::exists(engine);
  const ServerRun r = run(have ? script({{"file", engine.string()}})
                               : script({{"file", kNucleon}, {"iso", "60.5"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  const isotile::Mesh m = isotile::read_mesh(dir_ / "out.ply");
  EXPECT_GT(m.triangles.size(), have ? 500000u : 1000u);
  EXPECT_GT(isotile::triangle_quality(m).mean, 0.8);  // Macet
}

// `iso` nan chooses the isovalue; the script keeps the parameters of 2020-era scripts (a script
// lacking a declared parameter aborts meshlabserver 2020.09, so none was added for it).
TEST_F(MeshlabServer, IsoAutoGivesTheCliMeshAndLogsTheValue) {
  for (const char* memory : {"0", "256KiB"}) {
    const ServerRun r =
        run(script({{"file", kNucleon}, {"iso", "nan"}, {"method", "0"}, {"memory", memory}}));
    ASSERT_EQ(r.code, 0) << memory << "\n" << r.log;
    EXPECT_NE(r.log.find("(Otsu's threshold of the samples)"), std::string::npos) << r.log;
    expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"), cli(kNucleon + " --iso auto"), memory);
  }
}

TEST_F(MeshlabServer, BadInputFailsWithAMessageAndNoOutput) {
  struct Case {
    std::map<std::string, std::string> values;
    const char* says;
  } cases[] = {
      {{{"file", "/nonexistent/volume_8x8x8_uint8.raw"}}, "no such file"},
      {{{"file", kNucleon}, {"dims", "41,41"}}, "dims must be three comma-separated numbers"},
      {{{"file", kNucleon}, {"type", "uint12"}}, "unknown type 'uint12'"},
      {{{"file", kNucleon}, {"dc_vertices", "2"}, {"method", "2"}}, "dc_vertices must be one of"},
      {{{"file", kNucleon}, {"memory", "lots"}}, "lots"},
      {{{"file", kNucleon}, {"simplify", "0"}}, "simplify"},
      {{{"file", kNucleon}, {"series", "1.2.3"}}, "DICOM"},
      {{{"file", kNucleon}, {"iso", "1000"}}, "no surface at isovalue"},
  };
  for (const Case& c : cases) {
    const ServerRun r = run(script(c.values));
    EXPECT_NE(r.code, 0) << c.says << "\n" << r.log;
    EXPECT_NE(r.log.find(c.says), std::string::npos) << r.log;
    EXPECT_NE(r.log.find("Problem with filter"), std::string::npos) << r.log;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << c.says;
  }
}

TEST_F(MeshlabServer, BricksSimplificationAndTheSimplifyFilter) {
  // Brick by brick within 256 KiB: Marching Cubes' bricked mesh is the in-core one.
  ServerRun r =
      run(script({{"file", kNucleon}, {"iso", "60.5"}, {"method", "0"}, {"memory", "256KiB"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_EQ(r.log.find("1 brick(s)"), std::string::npos) << r.log;
  expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"), cli(kNucleon + " --iso 60.5"), "bricks");
  // The isosurface filter's own simplification, and the simplify filter on the layer.
  r = run(script({{"file", kNucleon}, {"iso", "60.5"}, {"simplify", "0.25"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  const isotile::Mesh full = cli(kNucleon + " --iso 60.5 --method macet");
  const isotile::Mesh quarter = isotile::read_mesh(dir_ / "out.ply");
  EXPECT_NEAR(static_cast<double>(quarter.triangles.size()), 0.25 * full.triangles.size(),
              0.02 * 0.25 * full.triangles.size());
  std::string two = script({{"file", kNucleon}, {"iso", "60.5"}});
  const std::string simplify =
      " <filter name=\"Simplification: Shape-Preserving Edge Collapse (isotile)\">\n"
      "  <Param type=\"RichFloat\" name=\"ratio\" value=\"0.1\"/>\n"
      "  <Param type=\"RichInt\" name=\"faces\" value=\"0\"/>\n"
      "  <Param type=\"RichFloat\" name=\"max_error\" value=\"0\"/>\n"
      "  <Param type=\"RichFloat\" name=\"min_quality\" value=\"0.3\"/>\n"
      " </filter>\n";
  two.insert(two.find("</FilterScript>"), simplify);
  r = run(two);
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.log.find("simplified"), std::string::npos) << r.log;
  const isotile::Mesh tenth = isotile::read_mesh(dir_ / "out.ply");
  EXPECT_NEAR(static_cast<double>(tenth.triangles.size()), 0.1 * full.triangles.size(),
              0.02 * 0.1 * full.triangles.size());
  const isotile::TopologyStats t = isotile::mesh_topology(tenth);
  EXPECT_EQ(t.nonmanifold_edges, 0u);
  EXPECT_EQ(t.euler, isotile::mesh_topology(full).euler);
  EXPECT_GE(isotile::triangle_quality(tenth).min, 0.2);
}

TEST_F(MeshlabServer, GlBackendsRunBesideMeshLabsOwnContext) {
  // MeshLab's GLX context is current on its thread; the plugin runs GL work on a thread of its
  // own. The geometry-shader and HistoPyramid paths give the CPU's Marching Cubes mesh.
  std::string gl_info = ISOTILE_CLI;
  gl_info += " gl-info > /dev/null 2>&1";
  const bool gl = std::system(gl_info.c_str()) == 0;
  const isotile::Mesh cpu = cli(kNucleon + " --iso 60.5");
  for (const char* backend : {"2", "3"}) {
    const ServerRun r =
        run(script({{"file", kNucleon}, {"iso", "60.5"}, {"method", "0"}, {"backend", backend}}));
    if (!gl) {
      // No OpenGL 4.5 here: an explicit GPU backend fails cleanly, naming why.
      EXPECT_NE(r.code, 0) << r.log;
      EXPECT_NE(r.log.find("isotile: "), std::string::npos) << r.log;
      continue;
    }
    ASSERT_EQ(r.code, 0) << backend << "\n" << r.log;
    const char* where = backend[0] == '2' ? "on gs" : "on hp";
    EXPECT_NE(r.log.find(where), std::string::npos) << r.log;
    expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"), cpu, backend);
  }
}

}  // namespace
