// `isotile render` and `extract --render` (shaders/mesh_render.h, tiler/render_command.cpp): the
// picture's size, the framed sphere's area, colours on the quality ramp (colour_ramp.h) and its
// colour bar, the same picture from every mesh format, in pieces and twice, one-line errors with
// no file left, the error without a context, and nothing GL alive at exit. Skips (SkipKind Gl)
// where no context can be made.
#include <gtest/gtest.h>
#include <png.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli_support.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "gl_test_support.h"
#include "shaders/colour_ramp.h"
#include "shaders/mesh_render.h"

namespace {

namespace fs = std::filesystem;
using isotile::testing::CliResult;
using isotile::testing::slurp;
using namespace isotile;

struct Png {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
  std::array<int, 3> at(int x, int y) const {
    const std::size_t i = (std::size_t(y) * width + x) * 3;
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
};

// Reads an 8-bit RGB PNG with libpng's simplified API; width 0 when it is not a valid PNG.
Png read_png(const fs::path& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  Png out;
  if (!png_image_begin_read_from_file(&image, path.c_str())) return out;
  image.format = PNG_FORMAT_RGB;
  std::vector<std::uint8_t> pixels(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, pixels.data(), 0, nullptr)) return out;
  out.width = static_cast<int>(image.width);
  out.height = static_cast<int>(image.height);
  out.rgb = std::move(pixels);
  return out;
}

bool white(const std::array<int, 3>& c) {
  return c[0] == 255 && c[1] == 255 && c[2] == 255;
}

std::array<int, 3> ramp_rgb(double q) {
  const auto c = gl::quality_colour(q);
  return {int(std::lround(c[0] * 255)), int(std::lround(c[1] * 255)), int(std::lround(c[2] * 255))};
}

int colour_distance(const std::array<int, 3>& a, const std::array<int, 3>& b) {
  return std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
}

class Render : public isotile::testing::CliTest {
 protected:
  // The sphere field's mesh (field:sphere:48, Marching Cubes), written once per test.
  void sphere(const std::string& name = "sphere.ply") {
    const CliResult r = run("extract field:sphere:48 -q -o " + name);
    ASSERT_EQ(r.code, 0) << r.err;
  }
};

#define REQUIRE_GL_CLI()                                                                   \
  do {                                                                                     \
    const CliResult info = run("gl-info");                                                 \
    if (info.code != 0) ISOTILE_SKIP(Gl, "isotile gl-info found no OpenGL: " << info.err); \
  } while (0)

// Framed to fit, the sphere is a disc whose diameter is the view's smaller side less the margins,
// from any direction; the picture has the size asked for.
TEST_F(Render, SphereIsADiscOfTheExpectedArea) {
  REQUIRE_GL_CLI();
  sphere();
  for (const char* view : {"front", "top", "iso", "30,-20"}) {
    const CliResult r =
        run(std::string("render sphere.ply -q --colour solid --size 260x200 --view ") + view +
            " -o s.png");
    ASSERT_EQ(r.code, 0) << r.err;
    const Png p = read_png(dir_ / "s.png");
    ASSERT_EQ(p.width, 260) << view;
    ASSERT_EQ(p.height, 200) << view;
    std::size_t covered = 0;
    for (int y = 0; y < p.height; ++y)
      for (int x = 0; x < p.width; ++x) covered += !white(p.at(x, y));
    const double radius = 200 * (1 - 2 * gl::kRenderMargin) / 2;
    const double expected = M_PI * radius * radius;
    EXPECT_NEAR(covered / expected, 1.0, 0.03) << view << ": " << covered << " of " << expected;
    // Centred: the middle pixel is covered, the corners are not.
    EXPECT_FALSE(white(p.at(130, 100))) << view;
    EXPECT_TRUE(white(p.at(0, 0)) && white(p.at(259, 199))) << view;
  }
}

// Only a quality picture has a minimum size (its colour bar): solid and normal pictures of one
// pixel or a few rows are drawn (heights under 8 were refused, naming the quality bar).
TEST_F(Render, SolidAndNormalPicturesOfAnySizeAreDrawn) {
  REQUIRE_GL_CLI();
  sphere();
  for (const auto& [colour, size, w, h] :
       {std::tuple{"solid", "1x1", 1, 1}, std::tuple{"normal", "100x7", 100, 7},
        std::tuple{"solid", "5x3", 5, 3}}) {
    const CliResult r = run(std::string("render sphere.ply -q --colour ") + colour + " --size " +
                            size + " -o small.png");
    ASSERT_EQ(r.code, 0) << colour << " " << size << ": " << r.err;
    const Png p = read_png(dir_ / "small.png");
    EXPECT_EQ(p.width, w) << size;
    EXPECT_EQ(p.height, h) << size;
    EXPECT_FALSE(white(p.at(w / 2, h / 2))) << colour << " " << size;  // the sphere's middle
  }
}

// Every pixel of a quality picture is the ramp's colour of some quality within the mesh's
// [min, max], dimmed by the light, and the colour bar is the ramp itself, left (0) to right (1).
TEST_F(Render, QualityColoursFollowTheRamp) {
  REQUIRE_GL_CLI();
  sphere();
  const CliResult r = run("render sphere.ply -q --size 420x360 -o q.png");
  ASSERT_EQ(r.code, 0) << r.err;
  const Png p = read_png(dir_ / "q.png");
  ASSERT_EQ(p.width, 420);
  const QualityStats q = triangle_quality(read_mesh(dir_ / "sphere.ply"));
  const gl::BarExtent bar = gl::colour_bar_extent(420, 360);
  const int band = 360 - gl::colour_bar_height(420, 360);
  // Candidate colours: the ramp at 400 qualities in [min, max] times lights in [0.35, 1].
  std::vector<std::array<double, 3>> ramp;
  for (int i = 0; i <= 400; ++i)
    ramp.push_back(gl::quality_colour(q.min + (q.max - q.min) * i / 400));
  std::size_t checked = 0, off = 0;
  for (int y = 0; y < band; y += 3)
    for (int x = 0; x < p.width; x += 3) {
      const auto c = p.at(x, y);
      if (white(c)) continue;
      ++checked;
      double best = 1e9;
      for (const auto& rc : ramp) {
        // The light that best scales this ramp colour onto the pixel.
        const double num = c[0] * rc[0] + c[1] * rc[1] + c[2] * rc[2];
        const double den = 255 * (rc[0] * rc[0] + rc[1] * rc[1] + rc[2] * rc[2]);
        const double s = std::clamp(num / den, 0.35, 1.0);
        double d = 0;
        for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(c[k] - s * rc[k] * 255));
        best = std::min(best, d);
      }
      off += best > 3.0;
    }
  EXPECT_GT(checked, 1000u);
  EXPECT_EQ(off, 0u) << "of " << checked << " mesh pixels";
  // The bar's middle row, tick columns (black) aside.
  const int y = (bar.top + bar.bottom) / 2;
  int ramp_pixels = 0;
  for (int x = bar.left; x < bar.right; ++x) {
    const auto c = p.at(x, y);
    if (c == std::array<int, 3>{0, 0, 0}) continue;
    ++ramp_pixels;
    EXPECT_LE(colour_distance(c, ramp_rgb((x - bar.left + 0.5) / (bar.right - bar.left))), 0)
        << "bar pixel " << x;
  }
  EXPECT_GT(ramp_pixels, bar.right - bar.left - 10);
  EXPECT_EQ(p.at(bar.left - 2, y), (std::array<int, 3>{255, 255, 255}));
}

// Two triangles facing the camera (full light): every covered pixel is exactly the ramp's colour
// of its triangle's quality, and each triangle shows.
TEST_F(Render, FacingTrianglesHaveTheirQualitysColour) {
  REQUIRE_GL();
  Mesh m;
  // In the x-z plane (seen from the front): an equilateral triangle and a thin one.
  m.positions = {{0, 0, 0}, {2, 0, 0}, {1, 0, 1.7320508f}, {3, 0, 0}, {7, 0, 0}, {3, 0, 0.8f}};
  m.triangles = {{0, 1, 2}, {3, 4, 5}};
  gl::RenderOptions o;
  o.width = 320;
  o.height = 240;
  gl::parse_view("front", o);
  gl::RenderStats stats;
  const gl::Picture pic = gl::render_mesh(m, o, &stats);
  const double q0 = radius_ratio(m.positions[0], m.positions[1], m.positions[2]);
  const double q1 = radius_ratio(m.positions[3], m.positions[4], m.positions[5]);
  EXPECT_NEAR(stats.quality_min, q1, 1e-12);
  EXPECT_NEAR(stats.quality_max, q0, 1e-12);
  const std::array<int, 3> c0 = ramp_rgb(q0), c1 = ramp_rgb(q1);
  ASSERT_GT(colour_distance(c0, c1), 40);
  int n0 = 0, n1 = 0, other = 0;
  const int band = o.height - gl::colour_bar_height(o.width, o.height);
  for (int y = 0; y < band; ++y)
    for (int x = 0; x < o.width; ++x) {
      const std::size_t i = (std::size_t(y) * o.width + x) * 3;
      const std::array<int, 3> c = {pic.rgb[i], pic.rgb[i + 1], pic.rgb[i + 2]};
      if (white(c)) continue;
      if (colour_distance(c, c0) <= 1)
        ++n0;
      else if (colour_distance(c, c1) <= 1)
        ++n1;
      else
        ++other;
    }
  EXPECT_GT(n0, 1000);
  EXPECT_GT(n1, 500);
  EXPECT_EQ(other, 0);
}

// A mesh without faces gives the background and a bar that says so, not an error.
TEST_F(Render, EmptyMeshGivesAnEmptyPicture) {
  REQUIRE_GL();
  gl::RenderOptions o;
  o.width = 200;
  o.height = 150;
  gl::RenderStats stats;
  const gl::Picture pic = gl::render_mesh(Mesh{}, o, &stats);
  EXPECT_EQ(stats.triangles, 0u);
  EXPECT_EQ(stats.pieces, 0u);
  const int band = o.height - gl::colour_bar_height(o.width, o.height);
  for (int i = 0; i < o.width * band * 3; ++i) ASSERT_EQ(pic.rgb[i], 255) << i;
  const gl::BarExtent bar = gl::colour_bar_extent(o.width, o.height);
  int black = 0;  // the words "no triangles" under the bar
  for (int y = bar.bottom; y < o.height; ++y)
    for (int x = 0; x < o.width; ++x) black += pic.rgb[(std::size_t(y) * o.width + x) * 3] == 0;
  EXPECT_GT(black, 40);
}

// The picture does not depend on how the triangles are cut into pieces, nor on the run.
TEST_F(Render, PiecesAndRunsGiveTheSamePicture) {
  REQUIRE_GL();
  sphere();
  const Mesh m = read_mesh(dir_ / "sphere.ply");
  gl::RenderOptions o;
  o.width = 300;
  o.height = 260;
  o.wireframe = true;
  o.zoom = 2;
  gl::RenderStats whole, cut;
  const gl::Picture a = gl::render_mesh(m, o, &whole);
  o.piece_triangles = 777;
  const gl::Picture b = gl::render_mesh(m, o, &cut);
  EXPECT_EQ(whole.pieces, 1u);
  EXPECT_EQ(cut.pieces, (m.triangles.size() + 776) / 777);
  EXPECT_GT(cut.pieces, 5u);
  EXPECT_TRUE(a.rgb == b.rgb);
  const gl::Picture c = gl::render_mesh(m, o);
  EXPECT_TRUE(b.rgb == c.rgb);
}

// A binary PLY is drawn from its file with its faces read in pieces (core/mesh/ply_face_stream.h):
// the picture of the mesh read whole, with or without normals in the file; an ASCII PLY (read
// whole) gives it too. A face past the vertices and a file cut short are errors.
TEST_F(Render, PlyFacesReadInPiecesGiveTheSamePicture) {
  REQUIRE_GL();
  ASSERT_EQ(run("extract field:torus:36 -q -o t.ply").code, 0);
  ASSERT_EQ(run("extract field:torus:36 -q --normals -o tn.ply").code, 0);
  ASSERT_EQ(run("extract field:torus:36 -q --ascii -o ta.ply").code, 0);
  gl::RenderOptions o;
  o.width = 240;
  o.height = 200;
  o.wireframe = true;
  gl::RenderStats whole, streamed;
  const Mesh mesh = read_mesh(dir_ / "t.ply");
  const gl::Picture a = gl::render_mesh(mesh, o, &whole);
  o.piece_triangles = 501;
  for (const char* name : {"t.ply", "tn.ply", "ta.ply"}) {
    const gl::Picture b = gl::render_mesh_file(dir_ / name, o, &streamed);
    EXPECT_TRUE(a.rgb == b.rgb) << name;
    EXPECT_EQ(streamed.triangles, mesh.triangles.size()) << name;
    EXPECT_GT(streamed.pieces, 5u) << name;
    EXPECT_EQ(streamed.quality_min, whole.quality_min) << name;
    EXPECT_EQ(streamed.quality_max, whole.quality_max) << name;
  }
  const QualityStats q = triangle_quality(mesh);
  EXPECT_EQ(whole.quality_min, q.min);
  EXPECT_EQ(whole.quality_max, q.max);
  EXPECT_NEAR(whole.quality_mean, q.mean, 1e-12);
  // Cut short: the header and vertices whole, half the faces.
  const std::string bytes = slurp(dir_ / "t.ply");
  const std::size_t faces_at = bytes.find("end_header\n") + 11 + mesh.positions.size() * 12;
  std::ofstream(dir_ / "cut.ply", std::ios::binary)
      << bytes.substr(0, faces_at + (bytes.size() - faces_at) / 2);
  EXPECT_THROW(gl::render_mesh_file(dir_ / "cut.ply", o), InputError);
  // One index past the vertices (the last face's last corner).
  std::string bad = bytes;
  const std::uint32_t past = static_cast<std::uint32_t>(mesh.positions.size());
  std::memcpy(bad.data() + bad.size() - 4, &past, 4);
  std::ofstream(dir_ / "bad.ply", std::ios::binary) << bad;
  EXPECT_THROW(gl::render_mesh_file(dir_ / "bad.ply", o), InputError);
  // A face count one short of the faces the file holds (the last face was left out of the
  // picture, exit 0), a count of none, and a newline after the last face: the reader of the whole
  // file refuses both, and so must the streamed one.
  const std::string count = "element face " + std::to_string(mesh.triangles.size()) + "\n";
  std::string fewer = bytes;
  ASSERT_NE(fewer.find(count), std::string::npos);
  fewer.replace(fewer.find(count), count.size(),
                "element face " + std::to_string(mesh.triangles.size() - 1) + "\n");
  std::ofstream(dir_ / "fewer.ply", std::ios::binary) << fewer;
  std::string none = bytes;
  none.replace(none.find(count), count.size(), "element face 0\n");
  std::ofstream(dir_ / "none.ply", std::ios::binary) << none;
  std::ofstream(dir_ / "newline.ply", std::ios::binary) << bytes + "\n";
  for (const char* name : {"fewer.ply", "none.ply", "newline.ply"}) {
    EXPECT_THROW(read_mesh(dir_ / name), InputError) << name;
    EXPECT_THROW(gl::render_mesh_file(dir_ / name, o), InputError) << name;
  }
  // A second x: the reader of the whole file refuses it, so the streamed one must not pick one.
  std::string twice =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nproperty float x\nelement face 1\n"
      "property list uchar uint vertex_indices\nend_header\n";
  const float corners[3][4] = {{0, 0, 0, 9}, {1, 0, 0, 9}, {0, 1, 0, 9}};
  twice.append(reinterpret_cast<const char*>(corners), sizeof(corners));
  const std::uint32_t face[3] = {0, 1, 2};
  twice += '\3';
  twice.append(reinterpret_cast<const char*>(face), sizeof(face));
  std::ofstream(dir_ / "twice.ply", std::ios::binary) << twice;
  EXPECT_THROW(read_mesh(dir_ / "twice.ply"), InputError);
  EXPECT_THROW(gl::render_mesh_file(dir_ / "twice.ply", o), InputError);
}

// Same inputs, same bytes; and the same picture from the mesh in every format the reader takes.
TEST_F(Render, SameBytesTwiceAndFromEveryFormat) {
  REQUIRE_GL_CLI();
  for (const char* ext : {"ply", "obj", "stl", "off"}) sphere(std::string("sphere.") + ext);
  const std::string opts = " -q --size 200x180 --wireframe --view 20,40 --zoom 1.5";
  ASSERT_EQ(run("render sphere.ply -o a.png" + opts).code, 0);
  ASSERT_EQ(run("render sphere.ply -o b.png" + opts).code, 0);
  const std::string a = slurp(dir_ / "a.png");
  EXPECT_GT(a.size(), 1000u);
  EXPECT_TRUE(a == slurp(dir_ / "b.png"));
  for (const char* ext : {"obj", "stl", "off"}) {
    const std::string out = std::string(ext) + ".png";
    const CliResult r = run(std::string("render sphere.") + ext + " -o " + out + opts);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(slurp(dir_ / out) == a) << ext;
  }
}

// The picture would replace the mesh it draws: refused, the mesh kept (through a link, it was
// replaced with exit 0).
TEST_F(Render, AnOutputThatIsTheInputIsRefused) {
  REQUIRE_GL_CLI();
  sphere();
  fs::copy_file(dir_ / "sphere.ply", dir_ / "mesh.png");
  fs::create_symlink("mesh.png", dir_ / "link.ply");
  const std::string before = slurp(dir_ / "mesh.png");
  const CliResult r = run("render link.ply -q -o mesh.png");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("is the same file as the input"), std::string::npos) << r.err;
  EXPECT_EQ(slurp(dir_ / "mesh.png"), before);
}

// Bad inputs: one error line, a non-zero exit, and no picture (nor a temporary) left.
TEST_F(Render, BadInputsAreOneLineErrorsWithNoFileLeft) {
  REQUIRE_GL_CLI();
  sphere();
  std::ofstream(dir_ / "bad.ply") << "ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n";
  const std::string sphere_bytes = slurp(dir_ / "sphere.ply");
  std::ofstream(dir_ / "cut.ply", std::ios::binary)
      << sphere_bytes.substr(0, sphere_bytes.size() - 1000);
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"render bad.ply -o p.png", "bad.ply"},
      {"render cut.ply -o p.png", "cut.ply"},
      {"render missing.ply -o p.png", "missing.ply"},
      {"render sphere.ply -o no/such/dir/p.png", "no/such/dir/p.png"},
      {"render sphere.ply -o p.png --size 0x0", "--size"},
      {"render sphere.ply -o p.png --size 300", "--size"},
      {"render sphere.ply -o p.png --view sideways", "--view"},
      {"render sphere.ply -o p.png --view 10,95", "--view"},
      {"render sphere.ply -o p.png --zoom 0", "--zoom"},
      {"render sphere.ply -o p.png --center 1,2", "--center"},
      {"render sphere.ply -o p.png --size 40x30", "colour bar"},
      {"render sphere.ply -o p.jpg", ".png"},
      {"extract field:sphere:20 -o e.ply --render e.jpg", ".png"},
  };
  for (const auto& [args, names] : cases) {
    const CliResult r = run(args + " -q");
    EXPECT_NE(r.code, 0) << args;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << args << ": " << r.err;
    EXPECT_EQ(r.err.rfind("isotile: error: ", 0), 0u) << args << ": " << r.err;
    EXPECT_NE(r.err.find(names), std::string::npos) << args << ": " << r.err;
    EXPECT_EQ(stray_files({"sphere.ply", "bad.ply", "cut.ply"}), std::vector<std::string>{})
        << args;
  }
}

// A header's counts are checked against the file before the streamed reader sizes anything by
// them (3e8 vertices in a 213-byte file took 3.5 GB and 9 s before the read found them missing).
TEST_F(Render, ACountTheFileCannotHoldIsRefusedAtOnce) {
  REQUIRE_GL_CLI();
  std::ofstream(dir_ / "big.ply", std::ios::binary)
      << "ply\nformat binary_little_endian 1.0\nelement vertex 300000000\nproperty float x\n"
         "property float y\nproperty float z\nelement face 1\n"
         "property list uchar int vertex_indices\nend_header\n"
      << std::string(36, '\0');
  const auto t0 = std::chrono::steady_clock::now();
  const CliResult r = run("render big.ply -o p.png -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("big.ply: element 'vertex' declares 300000000 records but the file has "
                       "only 36 bytes left"),
            std::string::npos)
      << r.err;
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  EXPECT_FALSE(fs::exists(dir_ / "p.png"));
}

// The picture does not depend on the mesh's scale: a cube 1e-40 or 6e37 across covers the
// pixels a unit cube covers (positions went to the device unscaled, and the matrix's entries or
// the coordinates fell below float's normal range: a blank picture, exit 0).
TEST_F(Render, TheMeshsScaleDoesNotChangeThePicture) {
  REQUIRE_GL_CLI();
  std::size_t unit_pixels = 0;
  for (const double scale : {1.0, 6e37, 1e-40}) {
    std::ofstream obj(dir_ / "cube.obj");
    obj.precision(17);
    for (int c = 0; c < 8; ++c)
      obj << "v " << (c & 1) * scale << ' ' << (c >> 1 & 1) * scale << ' ' << (c >> 2) * scale
          << '\n';
    obj << "f 1 3 2\nf 2 3 4\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\nf 3 7 8\nf 3 8 4\n"
           "f 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n";
    obj.close();
    const CliResult r = run("render cube.obj -o c.png -q --colour solid --size 160x120");
    ASSERT_EQ(r.code, 0) << scale << ": " << r.err;
    const Png p = read_png(dir_ / "c.png");
    std::size_t covered = 0;
    for (int y = 0; y < p.height; ++y)
      for (int x = 0; x < p.width; ++x) covered += !white(p.at(x, y));
    if (scale == 1.0) unit_pixels = covered;
    EXPECT_GT(covered, 2000u) << scale;
    EXPECT_EQ(covered, unit_pixels) << scale;
  }
}

// Without any context, render says why (as the GL backends do) and leaves no picture.
TEST_F(Render, WithoutAContextSaysWhy) {
  std::ofstream(dir_ / "t.off") << "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  const CliResult r = run("render t.off -q -o t.png", "ISOTILE_GL=off");
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err, "isotile: error: no OpenGL context: disabled by ISOTILE_GL=off\n");
  EXPECT_FALSE(fs::exists(dir_ / "t.png"));
}

// extract --render draws the written mesh: in core from memory, out of core from the file; both
// give the picture `isotile render` makes of the file.
TEST_F(Render, ExtractRenderDrawsTheWrittenMesh) {
  REQUIRE_GL_CLI();
  CliResult r = run("extract field:torus:40 -q -o core.ply --render core.png");
  ASSERT_EQ(r.code, 0) << r.err;
  r = run("extract field:torus:40 -q --memory 60KiB -o tiled.ply --render tiled.png");
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_EQ(run("render core.ply -q -o direct.png").code, 0);
  const std::string direct = slurp(dir_ / "direct.png");
  EXPECT_EQ(read_png(dir_ / "direct.png").width, 800);
  EXPECT_TRUE(slurp(dir_ / "core.png") == direct);
  EXPECT_TRUE(slurp(dir_ / "tiled.png") == direct);
}

// A picture that fails after the mesh was written (no context here): exit 1 and every output as
// it was, in core and out of core (the new mesh had replaced the old one, beside the old stats).
TEST_F(Render, AFailedPictureLeavesTheOutputsAsTheyWere) {
  for (const std::string& memory : {std::string(), std::string(" --memory 60KiB")}) {
    std::ofstream(dir_ / "m.ply") << "old mesh";
    std::ofstream(dir_ / "s.json") << "old stats";
    const CliResult r =
        run("extract field:torus:40 -q -o m.ply --stats s.json --render m.png" + memory,
            "ISOTILE_GL=off");
    EXPECT_EQ(r.code, 1) << memory;
    EXPECT_NE(r.err.find("no OpenGL context"), std::string::npos) << memory << ": " << r.err;
    EXPECT_EQ(slurp(dir_ / "m.ply"), "old mesh") << memory;
    EXPECT_EQ(slurp(dir_ / "s.json"), "old stats") << memory;
    EXPECT_FALSE(fs::exists(dir_ / "m.png")) << memory;
    EXPECT_EQ(stray_files({"m.ply", "s.json"}), std::vector<std::string>{}) << memory;
  }
}

// A render run ends GL in the known order: nothing left alive at exit (tests/gl_exit_check.c).
TEST_F(Render, LeavesNothingAliveAtExit) {
  REQUIRE_GL_CLI();
  sphere();
  const std::string preload = std::string("LD_PRELOAD='") + ISOTILE_GL_EXIT_CHECK +
                              "' ASAN_OPTIONS=\"$ASAN_OPTIONS:verify_asan_link_order=0\"";
  const CliResult r = run("--threads 8 render sphere.ply -q --wireframe -o p.png", preload);
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("gl_exit_check: nothing alive at exit: 0 EGL contexts (of 1 made)"),
            std::string::npos)
      << r.err;
}

}  // namespace
