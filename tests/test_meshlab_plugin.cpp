// The MeshLab plugin in the real meshlabserver (Debian's MeshLab 2020.09) under xvfb-run, driven
// by .mlx scripts made from the shipped example (meshlab_plugin/examples/isosurface.mlx), so that
// a parameter missing from the example fails here. The plugin loads from a private copy of
// MeshLab's layout in the test's folder: nothing on the system changes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "test_support.h"

namespace {

namespace fs = std::filesystem;

struct ServerRun {
  int code = -1;
  std::string log;  // standard output, then standard error
  std::string out;  // standard output alone
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
    // Both come with setup.sh's packages (meshlab, xvfb); without them every run here would fail
    // with a shell's "not found" instead of saying what is missing.
    if (!fs::exists("/usr/bin/meshlabserver"))
      ISOTILE_SKIP(Meshlab, "no /usr/bin/meshlabserver (Debian package meshlab)");
    if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0)
      ISOTILE_SKIP(Meshlab, "no xvfb-run on PATH (Debian package xvfb)");
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

  // meshlabserver running `mlx` (and writing `output` when given, with `options` such as
  // "-m fc fq sa" or "-i in.ply" added).
  ServerRun run(const std::string& mlx, const std::string& output = "out.ply",
                const std::string& options = "") {
    std::ofstream(dir_ / "script.mlx") << mlx;
    // No file of an earlier run may stand in for this one's.
    if (!output.empty()) fs::remove(dir_ / output);
    const std::string cmd = "cd '" + dir_.string() + "' && xvfb-run -a '" +
                            (dir_ / "prefix/bin/meshlabserver").string() + "' -s script.mlx" +
                            (output.empty() ? "" : " -o " + output) + " " + options +
                            " > log.txt 2> err.txt";
    const int status = std::system(cmd.c_str());
    ServerRun r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(dir_ / "log.txt");
    r.log = r.out + slurp(dir_ / "err.txt");
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

const std::string kSimplifyFilter =
    " <filter name=\"Simplification: Shape-Preserving Edge Collapse (isotile)\">\n"
    "  <Param type=\"RichFloat\" name=\"ratio\" value=\"0.1\"/>\n"
    "  <Param type=\"RichInt\" name=\"faces\" value=\"0\"/>\n"
    "  <Param type=\"RichFloat\" name=\"max_error\" value=\"0\"/>\n"
    "  <Param type=\"RichFloat\" name=\"min_quality\" value=\"0.3\"/>\n"
    " </filter>\n";

// `mlx` with the simplify filter appended.
std::string then_simplify(std::string mlx) {
  mlx.insert(mlx.find("</FilterScript>"), kSimplifyFilter);
  return mlx;
}

// The faces of an ASCII PLY that MeshLab wrote with face colour and quality (-m fc fq sa).
struct PlyFace {
  int rgb[3];
  float quality;
};
std::vector<PlyFace> read_ascii_ply_faces(const fs::path& file) {
  std::ifstream in(file);
  std::string line;
  std::size_t vertices = 0, faces = 0;
  std::vector<std::string> face_props;
  bool in_face = false;
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream w(line);
    std::string word, kind;
    w >> word;
    if (word == "element") {
      std::size_t n = 0;
      w >> kind >> n;
      in_face = kind == "face";
      (kind == "vertex" ? vertices : faces) = n;
    } else if (word == "property" && in_face) {
      std::string type, name;
      w >> type;
      if (type == "list") w >> type >> type;
      w >> name;
      face_props.push_back(name);
    }
  }
  for (std::size_t i = 0; i < vertices; ++i) std::getline(in, line);
  std::vector<PlyFace> out;
  for (std::size_t i = 0; i < faces && std::getline(in, line); ++i) {
    std::istringstream w(line);
    PlyFace f{{-1, -1, -1}, -1};
    for (const std::string& name : face_props) {
      if (name == "vertex_indices") {
        int n = 0, v = 0;
        w >> n;
        for (int k = 0; k < n; ++k) w >> v;
      } else if (name == "quality") {
        w >> f.quality;
      } else {
        int c = 0;
        w >> c;
        if (name == "red") f.rgb[0] = c;
        if (name == "green") f.rgb[1] = c;
        if (name == "blue") f.rgb[2] = c;
      }
    }
    out.push_back(f);
  }
  EXPECT_EQ(out.size(), faces) << file;
  return out;
}

// MeshLab's red-yellow-green-cyan-blue ramp over [0, 1] (vcg::Color4b::SetColorRamp), which the
// isosurface filter paints by quality.
void ramp(float v, int rgb[3]) {
  static const float stops[5][3] = {
      {255, 0, 0}, {255, 255, 0}, {0, 255, 0}, {0, 255, 255}, {0, 0, 255}};
  const float step = 0.25f;
  int seg = 0;
  if (v < 0) {
    v = 0;
  } else {
    while (seg < 4 && v >= step) {
      v -= step;
      ++seg;
    }
  }
  if (seg == 4) {
    for (int c = 0; c < 3; ++c) rgb[c] = static_cast<int>(stops[4][c]);
    return;
  }
  const float x = v / step;
  for (int c = 0; c < 3; ++c)
    rgb[c] = static_cast<int>(stops[seg + 1][c] * x + stops[seg][c] * (1.0f - x));
}

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

// Numbers typed in the script are the CLI's numbers: MeshLab keeps them as floats (60.3 as
// 60.29999924, 0.3 as 0.30000001), and the plugin reads back the decimal typed.
TEST_F(MeshlabServer, TypedDecimalsAreTheClisNumbers) {
  const ServerRun r = run(script({{"file", kNucleon},
                                  {"iso", "60.3"},
                                  {"method", "1"},
                                  {"macet_quality", "0"},
                                  {"macet_relax", "0.3"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"),
                   cli(kNucleon + " --iso 60.3 --method macet --macet-relax 0.3"), "relax 0.3");
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
    EXPECT_NE(r.out.find(" (automatic: Otsu's threshold of the samples)\n"), std::string::npos)
        << r.out;
    EXPECT_NE(r.out.find("isotile: samples from "), std::string::npos) << r.out;
    expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"), cli(kNucleon + " --iso auto"), memory);
  }
}

// A saved script (every field, in full) with another method's fields changed still runs: they
// are left out, and the log names them.
TEST_F(MeshlabServer, AnotherMethodsFieldsAreNamedInTheLog) {
  const ServerRun r = run(script({{"file", kNucleon},
                                  {"iso", "60.5"},
                                  {"method", "0"},
                                  {"dc_solver", "2"},
                                  {"macet_relax", "0.2"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.out.find("isotile: not used by Marching Cubes: Macet relax, DC solver\n"),
            std::string::npos)
      << r.out;
  expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"), cli(kNucleon + " --iso 60.5"), "mc");
}

TEST_F(MeshlabServer, BadInputFailsWithAMessageAndNoOutput) {
  struct Case {
    std::map<std::string, std::string> values;
    const char* says;
  } cases[] = {
      {{{"file", "/nonexistent/volume_8x8x8_uint8.raw"}}, "no such file"},
      {{{"file", kNucleon}, {"dims", "41,41"}}, "'Raw dims' must be three comma-separated numbers"},
      {{{"file", kNucleon}, {"type", "uint12"}}, "unknown 'Raw type' 'uint12'"},
      {{{"file", kNucleon}, {"dc_vertices", "2"}, {"method", "2"}}, "'DC vertices' must be one of"},
      {{{"file", kNucleon}, {"memory", "lots"}}, "lots"},
      {{{"file", kNucleon}, {"simplify", "0"}}, "'Simplify' must be in (0, 1]"},
      {{{"file", kNucleon}, {"series", "1.2.3"}}, "'DICOM series' applies to DICOM only"},
      {{{"file", kNucleon}, {"iso", "1000"}}, "no surface at isovalue"},
  };
  for (const Case& c : cases) {
    const ServerRun r = run(script(c.values));
    EXPECT_NE(r.code, 0) << c.says << "\n" << r.log;
    EXPECT_NE(r.log.find(c.says), std::string::npos) << r.log;
    // Once in meshlabserver's output.
    const std::size_t first = r.out.find(c.says);
    EXPECT_NE(first, std::string::npos) << r.out;
    EXPECT_EQ(r.out.find(c.says, first + 1), std::string::npos) << r.out;
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
  // It is `isotile extract --simplify`'s, in core and brick by brick (the same pipeline).
  expect_same_mesh(quarter, cli(kNucleon + " --iso 60.5 --method macet --simplify 0.25"),
                   "simplify");
  r = run(
      script({{"file", kNucleon}, {"iso", "60.5"}, {"simplify", "0.25"}, {"memory", "512KiB"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_EQ(r.log.find("1 brick(s)"), std::string::npos) << r.log;
  expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"),
                   cli(kNucleon + " --iso 60.5 --method macet --simplify 0.25 --memory 512KiB"),
                   "simplify brick by brick");
  r = run(then_simplify(script({{"file", kNucleon}, {"iso", "60.5"}})));
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

// Simplifying a layer the isosurface filter coloured by quality paints it again from the new
// faces' quality; other colours are dropped, saying so.
// A warning of the run (here a budget that Macet's one-cell slices of the nucleon overflow) is in
// MeshLab's log at its warning level, where a GUI user sees it, and not printed by the library on
// stderr (meshlabserver echoes its log there, as "LOG: LEVEL line"); the layer is still exact.
TEST_F(MeshlabServer, TheRunsWarningsAreInTheLog) {
  const ServerRun r =
      run(script({{"file", kNucleon}, {"iso", "60.5"}, {"method", "1"}, {"memory", "200000"}}));
  ASSERT_EQ(r.code, 0) << r.log;
  const std::string line =
      "isotile: warning: the memory budget of 200000 bytes is too small for this surface";
  EXPECT_NE(r.out.find(line), std::string::npos) << r.log;
  const std::string err = "\n" + slurp(dir_ / "err.txt");
  EXPECT_NE(err.find("\nLOG: 1 " + line), std::string::npos) << r.log;  // GLLogStream::WARNING
  EXPECT_EQ(err.find("\nisotile: warning:"), std::string::npos) << r.log;
  expect_same_mesh(isotile::read_mesh(dir_ / "out.ply"),
                   cli(kNucleon + " --iso 60.5 --method macet"), "warned");
}

TEST_F(MeshlabServer, SimplifyRecoloursTheQualityRampAndDropsOtherColours) {
  ServerRun r =
      run(then_simplify(script({{"file", kNucleon}, {"iso", "60.5"}})), "out.ply", "-m fc fq sa");
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.out.find("isotile: faces coloured again by their new quality\n"), std::string::npos)
      << r.log;
  const std::vector<PlyFace> faces = read_ascii_ply_faces(dir_ / "out.ply");
  ASSERT_GT(faces.size(), 100u);
  std::size_t off = 0, shades = 0;
  std::set<int> reds;
  for (const PlyFace& f : faces) {
    int want[3];
    ramp(f.quality, want);
    // The PLY holds the quality in decimal: one step of rounding either way.
    for (int c = 0; c < 3; ++c)
      if (std::abs(f.rgb[c] - want[c]) > 1) {
        ++off;
        break;
      }
    reds.insert(f.rgb[0] * 65536 + f.rgb[1] * 256 + f.rgb[2]);
  }
  shades = reds.size();
  EXPECT_EQ(off, 0u) << "of " << faces.size() << " faces";
  EXPECT_GT(shades, 50u);  // a ramp, not one colour
  const isotile::Mesh simplified = isotile::read_mesh(dir_ / "out.ply");
  const isotile::QualityStats q = isotile::triangle_quality(simplified);
  EXPECT_NEAR(
      q.min,
      std::min_element(faces.begin(), faces.end(),
                       [](const PlyFace& a, const PlyFace& b) { return a.quality < b.quality; })
          ->quality,
      1e-5);

  // Colours of its own (grey, not the ramp of the quality): dropped, and the log says so.
  {
    std::ifstream in(dir_ / "out.ply");
    std::ofstream grey(dir_ / "grey.ply");
    std::string line;
    bool body = false;
    std::size_t vertices = 0, seen = 0;
    while (std::getline(in, line)) {
      if (!body) {
        if (line.rfind("element vertex ", 0) == 0) vertices = std::stoul(line.substr(15));
        body = line == "end_header";
        grey << line << "\n";
        continue;
      }
      if (seen++ < vertices) {
        grey << line << "\n";
        continue;
      }
      // "3 a b c r g b alpha quality": the colour becomes 128 128 128.
      std::istringstream w(line);
      std::string n, a, b, c, red, green, blue, alpha, quality;
      w >> n >> a >> b >> c >> red >> green >> blue >> alpha >> quality;
      grey << n << " " << a << " " << b << " " << c << " 128 128 128 " << alpha << " " << quality
           << "\n";
    }
  }
  const std::string only_simplify =
      "<!DOCTYPE FilterScript>\n<FilterScript>\n" + kSimplifyFilter + "</FilterScript>\n";
  r = run(only_simplify, "out2.ply", "-i grey.ply");
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.out.find("isotile: dropped the layer's face colours"), std::string::npos) << r.log;
  EXPECT_EQ(r.out.find("coloured again"), std::string::npos) << r.log;
}

// A layer the simplify filter cannot bring to its target (faces saved unwelded, each with its
// own three vertices: every vertex on a border, which no collapse may move) gives the CLI's
// warning at MeshLab's warning level, with the way out MeshLab offers; it said only "simplified
// 10464 to 10464 triangles". A face selection is not a limit, and the log says it is gone.
TEST_F(MeshlabServer, TheSimplifyFilterSaysWhatItMissedAndWhatItIgnored) {
  const isotile::Mesh welded = cli(kNucleon + " --iso 60.5");
  isotile::Mesh soup;
  for (const isotile::Tri& t : welded.triangles) {
    isotile::Tri own;
    for (int k = 0; k < 3; ++k) {
      own[k] = static_cast<std::uint32_t>(soup.positions.size());
      soup.positions.push_back(welded.positions[t[k]]);
    }
    soup.triangles.push_back(own);
  }
  isotile::write_mesh(soup, dir_ / "soup.ply", {});
  const std::string only_simplify =
      "<!DOCTYPE FilterScript>\n<FilterScript>\n" + kSimplifyFilter + "</FilterScript>\n";
  ServerRun r = run(only_simplify, "out.ply", "-i soup.ply");
  ASSERT_EQ(r.code, 0) << r.log;
  const std::string warning = "isotile: warning: simplification stopped at " +
                              std::to_string(soup.triangles.size()) + " triangles";
  EXPECT_NE(r.out.find(warning), std::string::npos) << r.log;
  EXPECT_NE(r.out.find("an unwelded mesh? Merge its vertices first (Filters > Cleaning and "
                       "Repairing > Remove Duplicate Vertices)"),
            std::string::npos)
      << r.log;
  EXPECT_NE(slurp(dir_ / "err.txt").find("LOG: 1 " + warning), std::string::npos)
      << r.log;  // GLLogStream::WARNING
  // The welded layer reaches its target: no warning; with every face selected, the log says the
  // whole layer was simplified (MeshLab's Select All, from its own plugin).
  isotile::write_mesh(welded, dir_ / "welded.ply", {});
  fs::create_symlink("/usr/lib/x86_64-linux-gnu/meshlab/plugins/libfilter_select.so",
                     dir_ / "prefix/lib/x86_64-linux-gnu/meshlab/plugins/libfilter_select.so");
  const std::string select_all =
      " <filter name=\"Select All\">\n"
      "  <Param type=\"RichBool\" name=\"allFaces\" value=\"true\"/>\n"
      "  <Param type=\"RichBool\" name=\"allVerts\" value=\"true\"/>\n"
      " </filter>\n";
  r = run("<!DOCTYPE FilterScript>\n<FilterScript>\n" + select_all + kSimplifyFilter +
              "</FilterScript>\n",
          "out.ply", "-i welded.ply");
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_EQ(r.out.find("isotile: warning:"), std::string::npos) << r.log;
  EXPECT_NE(r.out.find("isotile: the whole layer was simplified; its selection of " +
                       std::to_string(welded.triangles.size()) + " faces was not kept"),
            std::string::npos)
      << r.log;
  r = run(only_simplify, "out.ply", "-i welded.ply");
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_EQ(r.out.find("selection"), std::string::npos) << r.log;
}

// meshlabserver prints progress texts with no line break: the plugin's end their own lines.
TEST_F(MeshlabServer, ProgressAndMessagesOneALine) {
  const ServerRun r = run(then_simplify(script({{"file", kNucleon}, {"iso", "60.5"}})));
  ASSERT_EQ(r.code, 0) << r.log;
  std::istringstream lines(r.out);
  int progress = 0;
  for (std::string line; std::getline(lines, line);) {
    const std::size_t at = line.find("isotile: ");
    if (at == std::string::npos) continue;
    EXPECT_EQ(at, 0u) << "'" << line << "' runs into what came before";
    EXPECT_EQ(line.find("isotile: ", at + 1), std::string::npos) << line;
    if (line.size() > 2 && line.compare(line.size() - 2, 2, "%)") == 0) ++progress;
  }
  // The progress is polled every 0.1 s, so a small volume shows the extraction's last stage
  // only; the simplify filter reports its start and end.
  EXPECT_GE(progress, 3) << r.out;
  EXPECT_NE(r.out.find("isotile: simplifying "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" triangles (100%)\n"), std::string::npos) << r.out;
  // The layer: a name without dots; the file and isovalue in full in the log.
  EXPECT_NE(r.out.find("isotile: layer 'nucleon_41x41x41_uint8 macet iso60_5': " + kNucleon +
                       ", Macet fast, isovalue 60.5\n"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("isotile: samples from "), std::string::npos) << r.out;
}

// The same file extracted twice in one document gives two layers of distinct, whole names.
TEST_F(MeshlabServer, ExtractingAgainGivesADistinctName) {
  std::string twice = script({{"file", kNucleon}, {"iso", "60.5"}, {"method", "0"}});
  const std::size_t begin = twice.find(" <filter ");
  const std::size_t end = twice.find("</FilterScript>");
  twice.insert(end, twice.substr(begin, end - begin));
  const ServerRun r = run(twice);
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.out.find("isotile: layer 'nucleon_41x41x41_uint8 mc iso60_5': "), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("isotile: layer 'nucleon_41x41x41_uint8 mc iso60_5 (2)': "),
            std::string::npos)
      << r.out;
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
  if (!gl)
    ISOTILE_SKIP(Gl,
                 "isotile gl-info found no OpenGL: only the clean failure of the GL "
                 "backends was checked, not their meshes");
}

}  // namespace
