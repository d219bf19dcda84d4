#include <fcntl.h>
#include <gtest/gtest.h>
#include <stdio_ext.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <bit>
#include <cctype>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/ply_face_stream.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

// A fresh directory per test, removed afterwards.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    path_ = fs::temp_directory_path() / ("isotile-test-mesh-io-" + std::to_string(::getpid()) +
                                         "-" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  fs::path operator/(const std::string& name) const { return path_ / name; }
  const fs::path& path() const { return path_; }
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(path_)) names.push_back(e.path().filename());
    std::sort(names.begin(), names.end());
    return names;
  }

 private:
  fs::path path_;
};

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good());
}

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Bitwise, so that -0 and +0 (and every last bit) must survive.
bool same_bits(const std::vector<Vec3f>& a, const std::vector<Vec3f>& b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3f)) == 0);
}

void expect_same_mesh(const Mesh& expected, const Mesh& actual) {
  EXPECT_TRUE(same_bits(expected.positions, actual.positions));
  EXPECT_TRUE(same_bits(expected.normals, actual.normals));
  EXPECT_EQ(expected.triangles, actual.triangles);
  EXPECT_EQ(expected.quads, actual.quads);
}

// Awkward floats: shortest decimal forms, extremes, subnormals, negative zero.
const std::vector<float> kTrickyFloats = {0.1f,
                                          -0.0f,
                                          1e-30f,
                                          std::numeric_limits<float>::denorm_min(),
                                          std::numeric_limits<float>::max(),
                                          -std::numeric_limits<float>::max(),
                                          1.0f / 3.0f,
                                          123456.789f,
                                          -7.25f,
                                          std::nextafter(1.0f, 2.0f),
                                          16777217.0f,
                                          3.0e-39f,
                                          std::numeric_limits<float>::min(),
                                          2.5f,
                                          -1e10f,
                                          0.0f};

// Five vertices with tricky coordinates, two triangles and one quad, unit normals.
Mesh small_mesh(bool normals, bool quads) {
  Mesh m;
  for (std::size_t i = 0; i < 5; ++i) {
    m.positions.push_back({kTrickyFloats[(3 * i) % kTrickyFloats.size()],
                           kTrickyFloats[(3 * i + 1) % kTrickyFloats.size()],
                           kTrickyFloats[(3 * i + 2) % kTrickyFloats.size()]});
  }
  if (normals) {
    m.normals = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.6f, 0.8f, 0}, {0, -0.6f, 0.8f}};
  }
  m.triangles = {{0, 1, 2}, {2, 3, 4}};
  if (quads) m.quads = {{0, 1, 3, 4}};
  return m;
}

// A grid large enough for many writer chunks, with random bit-pattern coordinates.
Mesh big_mesh(bool normals, bool quads) {
  std::mt19937 rng(12345);
  Mesh m;
  const std::uint32_t n = 150;
  auto random_float = [&] {
    for (;;) {
      const float f = std::bit_cast<float>(static_cast<std::uint32_t>(rng()));
      if (std::isfinite(f)) return f;
    }
  };
  for (std::uint32_t i = 0; i < n * n; ++i) {
    m.positions.push_back({random_float(), random_float(), random_float()});
    if (normals) m.normals.push_back({random_float(), random_float(), random_float()});
  }
  for (std::uint32_t y = 0; y + 1 < n; ++y) {
    for (std::uint32_t x = 0; x + 1 < n; ++x) {
      const std::uint32_t a = y * n + x, b = a + 1, c = a + n, d = c + 1;
      if (quads && (x + y) % 3 == 0) {
        m.quads.push_back({a, b, d, c});
      } else {
        m.triangles.push_back({a, b, d});
        m.triangles.push_back({a, d, c});
      }
    }
  }
  return m;
}

Mesh round_trip(const Mesh& m, const fs::path& path, MeshWriteOptions options = {}) {
  write_mesh(m, path, options);
  return read_mesh(path);
}

std::string error_of(const fs::path& path) {
  try {
    read_mesh(path);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no InputError)";
}

TEST(MeshFormat, FromExtension) {
  EXPECT_EQ(mesh_format_from_path("a/b.ply"), MeshFormat::Ply);
  EXPECT_EQ(mesh_format_from_path("B.PLY"), MeshFormat::Ply);
  EXPECT_EQ(mesh_format_from_path("x.Obj"), MeshFormat::Obj);
  EXPECT_EQ(mesh_format_from_path("x.stl"), MeshFormat::Stl);
  EXPECT_EQ(mesh_format_from_path("x.off"), MeshFormat::Off);
  EXPECT_THROW(mesh_format_from_path("x.vtk"), InputError);
  EXPECT_THROW(mesh_format_from_path("ply"), InputError);
}

TEST(MeshRoundTrip, PlyBinary) {
  TempDir dir;
  for (bool normals : {false, true}) {
    for (bool quads : {false, true}) {
      SCOPED_TRACE(::testing::Message() << "normals " << normals << " quads " << quads);
      const Mesh m = small_mesh(normals, quads);
      expect_same_mesh(m, round_trip(m, dir / "m.ply"));
      const Mesh big = big_mesh(normals, quads);
      expect_same_mesh(big, round_trip(big, dir / "big.ply"));
    }
  }
  // Header as documented, then 3 floats per vertex and "3 a b c" with a uchar count.
  const Mesh m = small_mesh(false, false);
  write_mesh(m, dir / "m.ply");
  const std::string bytes = read_bytes(dir / "m.ply");
  const std::string header_end = "end_header\n";
  const std::size_t data = bytes.find(header_end) + header_end.size();
  EXPECT_NE(bytes.find("format binary_little_endian 1.0\n"), std::string::npos);
  EXPECT_NE(bytes.find("element vertex 5\n"), std::string::npos);
  EXPECT_NE(bytes.find("element face 2\nproperty list uchar uint vertex_indices\n"),
            std::string::npos);
  EXPECT_EQ(bytes.size(), data + 5 * 12 + 2 * 13);
  EXPECT_EQ(bytes[data + 60], 3);
}

TEST(MeshRoundTrip, PlyAscii) {
  TempDir dir;
  MeshWriteOptions ascii;
  ascii.ascii = true;
  for (bool normals : {false, true}) {
    for (bool quads : {false, true}) {
      SCOPED_TRACE(::testing::Message() << "normals " << normals << " quads " << quads);
      const Mesh m = small_mesh(normals, quads);
      expect_same_mesh(m, round_trip(m, dir / "m.ply", ascii));
      const Mesh big = big_mesh(normals, quads);
      expect_same_mesh(big, round_trip(big, dir / "big.ply", ascii));
    }
  }
  write_mesh(small_mesh(false, true), dir / "m.ply", ascii);
  const std::string text = read_bytes(dir / "m.ply");
  EXPECT_NE(text.find("format ascii 1.0\n"), std::string::npos);
  EXPECT_NE(text.find("\n3 0 1 2\n3 2 3 4\n4 0 1 3 4\n"), std::string::npos);
}

TEST(MeshRoundTrip, PlyWithoutNormalsWhenAsked) {
  TempDir dir;
  MeshWriteOptions options;
  options.write_normals = false;
  const Mesh m = small_mesh(true, false);
  const Mesh back = round_trip(m, dir / "m.ply", options);
  EXPECT_TRUE(back.normals.empty());
  EXPECT_TRUE(same_bits(m.positions, back.positions));
}

TEST(MeshRoundTrip, Obj) {
  TempDir dir;
  for (bool normals : {false, true}) {
    for (bool quads : {false, true}) {
      SCOPED_TRACE(::testing::Message() << "normals " << normals << " quads " << quads);
      const Mesh m = small_mesh(normals, quads);
      expect_same_mesh(m, round_trip(m, dir / "m.obj"));
      const Mesh big = big_mesh(normals, quads);
      expect_same_mesh(big, round_trip(big, dir / "big.obj"));
    }
  }
  write_mesh(small_mesh(true, false), dir / "m.obj");
  EXPECT_NE(read_bytes(dir / "m.obj").find("\nf 1//1 2//2 3//3\n"), std::string::npos);
}

TEST(MeshRoundTrip, Off) {
  TempDir dir;
  for (bool quads : {false, true}) {
    SCOPED_TRACE(::testing::Message() << "quads " << quads);
    const Mesh m = small_mesh(false, quads);
    expect_same_mesh(m, round_trip(m, dir / "m.off"));
    const Mesh big = big_mesh(false, quads);
    expect_same_mesh(big, round_trip(big, dir / "big.off"));
  }
  // OFF has no per-vertex normals here: they are dropped, the rest survives.
  const Mesh back = round_trip(small_mesh(true, false), dir / "n.off");
  EXPECT_TRUE(back.normals.empty());
  EXPECT_EQ(read_bytes(dir / "n.off").substr(0, 10), "OFF\n5 2 0\n");
}

TEST(MeshRoundTrip, StlWeldsAndSplitsQuads) {
  TempDir dir;
  // Positions listed in order of first use by the written triangles, so welding restores them.
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.1f, -0.0f, 1e-30f}};
  m.triangles = {{0, 1, 2}};
  m.quads = {{0, 2, 3, 4}};
  const Mesh back = round_trip(m, dir / "m.stl");
  Mesh expected;
  // -0 welds with +0, and a welded position is stored as +0.
  expected.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.1f, 0.0f, 1e-30f}};
  expected.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}};
  expect_same_mesh(expected, back);

  const std::string bytes = read_bytes(dir / "m.stl");
  ASSERT_EQ(bytes.size(), 84u + 3 * 50);
  EXPECT_NE(bytes.substr(0, 5), "solid");
  std::uint32_t count;
  std::memcpy(&count, bytes.data() + 80, 4);
  EXPECT_EQ(count, 3u);
  float normal[3];
  std::memcpy(normal, bytes.data() + 84, 12);
  EXPECT_EQ(normal[0], 0.0f);
  EXPECT_EQ(normal[1], 0.0f);
  EXPECT_EQ(normal[2], 1.0f);

  // Duplicated positions in the input become one vertex.
  Mesh dup;
  dup.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  dup.triangles = {{0, 1, 2}, {3, 5, 4}};
  const Mesh welded = round_trip(dup, dir / "dup.stl");
  EXPECT_EQ(welded.positions.size(), 4u);
  EXPECT_EQ(welded.triangles, (std::vector<Tri>{{0, 1, 2}, {1, 3, 2}}));

  const Mesh big = big_mesh(false, true);
  const Mesh big_back = round_trip(big, dir / "big.stl");
  EXPECT_EQ(big_back.triangles.size(), big.triangles.size() + 2 * big.quads.size());
}

// STL holds triangles: a quad is cut on the diagonal the quality measure takes (the better worst
// triangle), not always on 0-2, so the file holds the triangles its stats described.
TEST(MeshRoundTrip, StlCutsQuadsOnTheBetterDiagonal) {
  TempDir dir;
  Mesh m;  // a flat kite: 0-2 is its long diagonal, which would leave two slivers
  m.positions = {{0, 0, 0}, {1, -0.2f, 0}, {2, 0, 0}, {1, 0.2f, 0}};
  m.quads = {{0, 1, 2, 3}};
  const Mesh back = round_trip(m, dir / "kite.stl");
  EXPECT_EQ(back.triangles, (std::vector<Tri>{{0, 1, 2}, {1, 3, 2}}));  // welded: 0 1 3, 1 2 3
  EXPECT_EQ(back.positions,
            (std::vector<Vec3f>{{0, 0, 0}, {1, -0.2f, 0}, {1, 0.2f, 0}, {2, 0, 0}}));
  const QuadSplit split = split_quad(m.positions, m.quads[0]);
  EXPECT_EQ(split.triangles, (std::array<Tri, 2>{Tri{0, 1, 3}, Tri{1, 2, 3}}));
  EXPECT_EQ(triangle_quality(back).min, triangle_quality(m).min);
}

TEST(MeshRoundTrip, ExplicitFormatOverridesExtension) {
  TempDir dir;
  MeshWriteOptions options;
  options.format = MeshFormat::Obj;
  write_mesh(small_mesh(false, false), dir / "m.ply", options);
  EXPECT_EQ(read_bytes(dir / "m.ply").substr(0, 1), "#");
}

TEST(MeshRoundTrip, EmptyMesh) {
  TempDir dir;
  for (const char* name : {"e.ply", "e.obj", "e.off", "e.stl"}) {
    SCOPED_TRACE(name);
    expect_same_mesh(Mesh{}, round_trip(Mesh{}, dir / name));
  }
}

// Appends big-endian bytes of any scalar.
template <class T>
void put_be(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  for (std::size_t i = 0; i < sizeof(T); ++i) s += b[sizeof(T) - 1 - i];
}

TEST(MeshReader, PlyBigEndianWithExtraProperties) {
  TempDir dir;
  std::string s =
      "ply\n"
      "format binary_big_endian 1.0\n"
      "comment hand-made: doubles, skipped scalars and lists, an extra element\n"
      "element vertex 5\n"
      "property double x\n"
      "property uchar red\n"
      "property double y\n"
      "property double z\n"
      "property list uchar int16 extra\n"
      "element material 2\n"
      "property float shininess\n"
      "element face 3\n"
      "property int flags\n"
      "property list int uint vertex_index\n"
      "end_header\n";
  const double xyz[5][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.5}, {-2.5, 1e-3, 7}};
  for (int v = 0; v < 5; ++v) {
    put_be(s, xyz[v][0]);
    put_be(s, std::uint8_t{200});
    put_be(s, xyz[v][1]);
    put_be(s, xyz[v][2]);
    put_be(s, static_cast<std::uint8_t>(v % 3));  // list length 0, 1 or 2
    for (int k = 0; k < v % 3; ++k) put_be(s, std::int16_t{-1});
  }
  put_be(s, 1.5f);
  put_be(s, 2.5f);
  auto face = [&](std::vector<std::uint32_t> corners) {
    put_be(s, std::int32_t{-7});
    put_be(s, static_cast<std::int32_t>(corners.size()));
    for (std::uint32_t c : corners) put_be(s, c);
  };
  face({0, 1, 2});
  face({0, 1, 2, 3});
  // Cut by ear clipping, seen along x (its Newell normal's largest part), where corners 0 and 1
  // meet: neither is an ear.
  face({0, 1, 2, 3, 4});
  write_bytes(dir / "be.ply", s);

  const Mesh m = read_mesh(dir / "be.ply");
  ASSERT_EQ(m.positions.size(), 5u);
  for (int v = 0; v < 5; ++v) {
    for (int k = 0; k < 3; ++k) EXPECT_EQ(m.positions[v][k], static_cast<float>(xyz[v][k]));
  }
  EXPECT_TRUE(m.normals.empty());
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {1, 2, 3}, {1, 3, 4}, {0, 1, 4}}));
  EXPECT_EQ(m.quads, (std::vector<Quad>{{0, 1, 2, 3}}));
}

TEST(MeshReader, PlyAsciiHandWritten) {
  TempDir dir;
  // CRLF line ends, integer coordinates, normals out of order, a skipped element before faces.
  const std::string s =
      "ply\r\nformat ascii 1.0\r\nobj_info made by hand\r\n"
      "element vertex 3\r\n"
      "property int x\r\nproperty float nz\r\nproperty short y\r\nproperty double z\r\n"
      "property float nx\r\nproperty float ny\r\nproperty list uint8 float uv\r\n"
      "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
      "element face 1\r\nproperty list uint8 uint32 vertex_indices\r\nproperty uchar flag\r\n"
      "end_header\r\n"
      "1 1 2 3.5 0 0 2 0.5 0.5\r\n"
      "-4 0.5 -5 0.1 0.6 0.8 0\r\n"
      "0 1 0 0 0 0 1 0.25\r\n"
      "0 1\r\n"
      "3 2 1 0 9\r\n";
  write_bytes(dir / "a.ply", s);
  const Mesh m = read_mesh(dir / "a.ply");
  EXPECT_TRUE(same_bits(m.positions, {{1, 2, 3.5f}, {-4, -5, 0.1f}, {0, 0, 0}}));
  EXPECT_TRUE(same_bits(m.normals, {{0, 0, 1}, {0.6f, 0.8f, 0.5f}, {0, 0, 1}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{2, 1, 0}}));
}

TEST(MeshReader, DoublesRoundToNearestFloat) {
  TempDir dir;
  // FLT_MAX printed to 8 digits is slightly above it as a double yet rounds back to FLT_MAX;
  // 0.1 rounds once; 1e-50 underflows to 0. 3.5e38 is past the halfway point to 2^128 and becomes
  // infinity, which is no position: refused, naming the file and the vertex.
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
      "property double z\nend_header\n3.4028235e38 -3.4028235e38 0.1\n";
  write_bytes(dir / "d.ply", head + "1 -1 1e-50\n");
  const Mesh m = read_mesh(dir / "d.ply");
  const float max = std::numeric_limits<float>::max();
  EXPECT_TRUE(same_bits(m.positions, {{max, -max, 0.1f}, {1.0f, -1.0f, 0.0f}}));
  write_bytes(dir / "inf.ply", head + "3.5e38 -3.5e38 0\n");
  try {
    read_mesh(dir / "inf.ply");
    ADD_FAILURE() << "an infinite position was read";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              (dir / "inf.ply").string() +
                  ": vertex 1 has a coordinate that is not a finite number (inf: infinite, or "
                  "past float32's largest, 3.4e38)");
  }
}

// A coordinate below float's range reads as 0 in every text format, as PLY's doubles did (OBJ,
// OFF, ASCII STL and float PLY called 1e-50 a bad number), and so does one below double's range
// (1e-400 was a bad number where 1e-320 read as 0), its sign kept; one above double's range is
// infinite, as one above float's is.
TEST(MeshReader, TinyCoordinatesUnderflowToZeroInEveryTextFormat) {
  TempDir dir;
  for (const std::string x : {"1e-50", "-1e-400", "0.0000000001e-399"}) {
    SCOPED_TRACE(x);
    write_bytes(dir / "t.obj", "v " + x + " 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write_bytes(dir / "t.off", "OFF\n3 1 0\n" + x + " 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    for (const char* type : {"float", "double"})
      write_bytes(dir / (std::string(type) + ".ply"),
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty " + std::string(type) +
                      " x\nproperty float y\nproperty float z\nelement face 1\n"
                      "property list uchar int vertex_indices\nend_header\n" +
                      x + " 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    write_bytes(dir / "t.stl", "solid s\nfacet normal 0 0 1\nouter loop\nvertex " + x +
                                   " 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n"
                                   "endsolid s\n");
    for (const char* name : {"t.obj", "t.off", "float.ply", "double.ply", "t.stl"}) {
      const Mesh m = read_mesh(dir / name);
      ASSERT_EQ(m.positions.size(), 3u) << name;
      EXPECT_EQ(m.positions[0][0], 0.0f) << name;
      // (STL's corners are welded by position, -0 as 0.)
      if (std::string(name) != "t.stl") {
        EXPECT_EQ(std::signbit(m.positions[0][0]), x[0] == '-') << name;
      }
    }
  }
  write_bytes(dir / "big.obj", "v 1 0 0\nv -1e400 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_NE(error_of(dir / "big.obj")
                .find("vertex 1 has a coordinate that is not a finite number "
                      "(-inf: infinite, or past float32's largest"),
            std::string::npos)
      << error_of(dir / "big.obj");
}

TEST(MeshReader, ObjHandWritten) {
  TempDir dir;
  const std::string s =
      "# a comment\n"
      "mtllib none.mtl\n"
      "o thing\n"
      "v 0 0 0\n"
      "v 1 0 0\n"
      "v 1 1 0 1.0\n"          // w
      "v 0 1 0 0.5 0.5 0.5\n"  // vertex colour
      "vt 0 0\n"
      "vn 0 0 1\n"
      "\n"
      "f 1/1/1 2/1/1 3/1/1\n"
      "f -4//-1 -2//-1 -1//-1   # trailing comment\n"
      "usemtl x\n"
      "s off\n"
      "v 0.5 2 0\n"
      "f 1 2 3 4\n"
      "f 1/1 2/1 3/1/ 4/1 5/1\n"
      "g group\n";
  write_bytes(dir / "h.obj", s);
  const Mesh m = read_mesh(dir / "h.obj");
  EXPECT_TRUE(same_bits(m.positions, {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, 2, 0}}));
  // One normal for five positions does not map onto per-position normals.
  EXPECT_TRUE(m.normals.empty());
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}, {0, 1, 2}, {0, 2, 3}, {0, 3, 4}}));
  EXPECT_EQ(m.quads, (std::vector<Quad>{{0, 1, 2, 3}}));
}

// A UTF-8 byte order mark before the first vertex (Notepad saves one): the vertex is read (it
// was skipped as an unknown keyword, and every corner pointed one vertex further on).
TEST(MeshReader, ObjAfterAByteOrderMark) {
  TempDir dir;
  write_bytes(dir / "b.obj", "\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n");
  const Mesh m = read_mesh(dir / "b.obj");
  EXPECT_TRUE(same_bits(m.positions, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
}

TEST(MeshReader, OffHandWritten) {
  TempDir dir;
  const std::string s =
      "COFF 5 3 0\n"
      "# colours follow the coordinates\n"
      "0 0 0 255 0 0 255\n"
      "1 0 0 255 0 0 255\n"
      "\n"
      "1 1 0 255 0 0 255\n"
      "0 1 0 255 0 0 255\n"
      "0.5 2 0 255 0 0 255\n"
      "3 0 1 2\n"
      "4 0 1 2 3 0.5 0.5 0.5\n"
      "5 0 1 2 3 4\n";
  write_bytes(dir / "h.off", s);
  const Mesh m = read_mesh(dir / "h.off");
  EXPECT_TRUE(same_bits(m.positions, {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, 2, 0}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 1, 2}, {0, 2, 3}, {0, 3, 4}}));
  EXPECT_EQ(m.quads, (std::vector<Quad>{{0, 1, 2, 3}}));
}

TEST(MeshReader, StlAscii) {
  TempDir dir;
  const std::string s =
      "solid first\n"
      "  facet normal 0 0 1\n"
      "    outer loop\n"
      "      vertex 0 0 0\n"
      "      vertex 1 0 0\n"
      "      vertex 0 1 0\n"
      "    endloop\n"
      "  endfacet\n"
      "endsolid first\n"
      "solid second\n"
      "  facet normal 0 0 0\n"
      "    outer loop\n"
      "      vertex 1 0 0\n"
      "      vertex 1 1 -0\n"
      "      vertex 0 1 0\n"
      "    endloop\n"
      "  endfacet\n"
      "endsolid\n";
  write_bytes(dir / "a.stl", s);
  // Keywords in capitals too, as some CAD exporters write them ("SOLID", "FACET NORMAL").
  std::string upper = s;
  for (char& c : upper) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  write_bytes(dir / "upper.stl", upper);
  for (const char* name : {"a.stl", "upper.stl"}) {
    SCOPED_TRACE(name);
    const Mesh m = read_mesh(dir / name);
    EXPECT_TRUE(same_bits(m.positions, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}));
    EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {1, 3, 2}}));
  }
}

// A binary STL whose header begins with "solid" is still binary when its size says so.
TEST(MeshReader, StlBinaryStartingWithSolid) {
  TempDir dir;
  std::string s(80, ' ');
  s.replace(0, 11, "solid thing");
  const std::uint32_t count = 1;
  s.append(reinterpret_cast<const char*>(&count), 4);
  const float tri[12] = {0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0};
  s.append(reinterpret_cast<const char*>(tri), sizeof(tri));
  s.append(2, '\0');
  write_bytes(dir / "b.stl", s);
  const Mesh m = read_mesh(dir / "b.stl");
  EXPECT_TRUE(same_bits(m.positions, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
}

// 64-bit face indices and counts (isotile's tiler writes uint64 indices past 2^32 - 1
// vertices); an index beyond int64's range is named as too large, not as negative.
TEST(MeshReader, Ply64BitIndices) {
  TempDir dir;
  for (const char* type : {"uint64", "int64"}) {
    SCOPED_TRACE(type);
    std::string s = std::string("ply\nformat binary_big_endian 1.0\nelement vertex 4\n") +
                    "property float x\nproperty float y\nproperty float z\nelement face 2\n" +
                    "property list uint64 " + type + " vertex_indices\nend_header\n";
    for (int v = 0; v < 4; ++v)
      for (int k = 0; k < 3; ++k) put_be(s, static_cast<float>(v == k + 1));
    put_be(s, std::uint64_t{3});
    for (std::uint64_t c : {0, 1, 2}) put_be(s, c);
    put_be(s, std::uint64_t{4});
    for (std::uint64_t c : {0, 1, 2, 3}) put_be(s, c);
    write_bytes(dir / "i64.ply", s);
    const Mesh m = read_mesh(dir / "i64.ply");
    EXPECT_EQ(m.positions.size(), 4u);
    EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
    EXPECT_EQ(m.quads, (std::vector<Quad>{{0, 1, 2, 3}}));
  }
  std::string s =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uchar uint64 vertex_indices\nend_header\n";
  for (int k = 0; k < 9; ++k) put_be(s, 0.0f);
  put_be(s, std::uint8_t{3});
  for (std::uint64_t c : {std::uint64_t{0}, std::uint64_t{1}, ~std::uint64_t{0}}) put_be(s, c);
  write_bytes(dir / "huge.ply", s);
  EXPECT_NE(error_of(dir / "huge.ply").find("references vertex 9223372036854775807"),
            std::string::npos)
      << error_of(dir / "huge.ply");
}

// Two properties of one name: which holds the value is each reader's guess, so none is taken.
TEST(MeshReader, PlyPropertyTwiceIsRefused) {
  TempDir dir;
  write_bytes(dir / "xx.ply",
              "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nproperty float x\nelement face 1\n"
              "property list uchar int vertex_indices\nend_header\n"
              "0 0 0 5\n1 0 0 6\n0 1 0 7\n3 0 1 2\n");
  EXPECT_NE(error_of(dir / "xx.ply").find("element 'vertex' has a second property 'x'"),
            std::string::npos)
      << error_of(dir / "xx.ply");
}

// Polygons of five or more corners are cut into ears, so that every triangle lies inside them: a
// fan from the first corner folded over a concave one (an L from its outer corner: a triangle
// turned over, outside the L). A convex polygon still gives the fan, as before.
TEST(MeshReader, ConcavePolygonsAreCutIntoEars) {
  TempDir dir;
  // An L of area 3 from its outer corner (2, 0), tilted out of every axis plane, counter-clockwise
  // and (the same corners reversed) clockwise; and a convex pentagon.
  const double l[6][2] = {{2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}, {0, 0}};
  std::string obj, off_vertices;
  for (const auto& p : l) {
    const std::string v = std::to_string(p[0]) + " " + std::to_string(p[1]) + " " +
                          std::to_string(0.5 * p[0] - 0.25 * p[1]);
    obj += "v " + v + "\n";
    off_vertices += v + "\n";
  }
  obj += "v 5 0 0\nv 6 0 0\nv 6.5 1 0\nv 5.5 2 0\nv 4.5 1 0\n";
  off_vertices += "5 0 0\n6 0 0\n6.5 1 0\n5.5 2 0\n4.5 1 0\n";
  write_bytes(dir / "l.obj", obj + "f 1 2 3 4 5 6\nf 6 5 4 3 2 1\nf 7 8 9 10 11\n");
  write_bytes(dir / "l.off",
              "OFF\n11 3 0\n" + off_vertices + "6 0 1 2 3 4 5\n6 5 4 3 2 1 0\n5 6 7 8 9 10\n");
  std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex 11\nproperty float x\n"
      "property float y\nproperty float z\nelement face 3\n"
      "property list uchar uint vertex_indices\nend_header\n";
  const Mesh from_obj = read_mesh(dir / "l.obj");
  for (const Vec3f& p : from_obj.positions) ply.append(reinterpret_cast<const char*>(&p), 12);
  for (const std::vector<std::uint32_t>& f : std::vector<std::vector<std::uint32_t>>{
           {0, 1, 2, 3, 4, 5}, {5, 4, 3, 2, 1, 0}, {6, 7, 8, 9, 10}}) {
    ply += static_cast<char>(f.size());
    ply.append(reinterpret_cast<const char*>(f.data()), 4 * f.size());
  }
  write_bytes(dir / "l.ply", ply);
  for (const char* name : {"l.obj", "l.off", "l.ply"}) {
    SCOPED_TRACE(name);
    const Mesh m = read_mesh(dir / name);
    ASSERT_EQ(m.triangles.size(), 4u + 4u + 3u);
    // Each L's triangles face the way the L does (its normal, up the tilted plane's z), cover
    // area 3, and use the L's corners only.
    for (int side = 0; side < 2; ++side) {
      double area = 0;
      for (int t = 0; t < 4; ++t) {
        const Tri& tri = m.triangles[4 * side + t];
        const Vec3f &a = m.positions[tri[0]], &b = m.positions[tri[1]], &c = m.positions[tri[2]];
        // Seen along z, the plane's area scale does not matter for the sign or the sum.
        const double z = (double(b[0]) - a[0]) * (double(c[1]) - a[1]) -
                         (double(b[1]) - a[1]) * (double(c[0]) - a[0]);
        EXPECT_GT(side == 0 ? z : -z, 0) << "triangle " << 4 * side + t << " turned over";
        area += 0.5 * std::abs(z);
        for (std::uint32_t v : tri) EXPECT_LT(v, 6u);
      }
      EXPECT_NEAR(area, 3, 1e-6) << (side == 0 ? "counter-clockwise" : "clockwise");
    }
    EXPECT_EQ(std::vector<Tri>(m.triangles.begin() + 8, m.triangles.end()),
              (std::vector<Tri>{{6, 7, 8}, {6, 8, 9}, {6, 9, 10}}));
    EXPECT_TRUE(m.quads.empty());
  }
  // render's streamed reader cuts them the same way.
  std::optional<PlyFaceStream> stream = PlyFaceStream::open(dir / "l.ply");
  ASSERT_TRUE(stream.has_value());
  std::vector<Tri> streamed, piece;
  while (stream->next(1, piece)) {  // a face at a time
    streamed.insert(streamed.end(), piece.begin(), piece.end());
    piece.clear();
  }
  EXPECT_EQ(streamed, read_mesh(dir / "l.ply").triangles);
  // A polygon of more corners than ear clipping gets through in seconds is refused, not cut for
  // hours.
  std::string big = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf";
  for (int c = 0; c < 65537; ++c) big += " " + std::to_string(c % 3 + 1);
  write_bytes(dir / "big.obj", big + "\n");
  EXPECT_NE(error_of(dir / "big.obj")
                .find("a face of 65537 corners (polygons of more than 65536 "
                      "are not read)"),
            std::string::npos)
      << error_of(dir / "big.obj");
}

// Lines ended by a carriage return alone (classic Mac OS) are lines: an OBJ read as one vertex
// and no face, exit 0 (the rest of the first `v` line, skipped, was the whole file).
TEST(MeshReader, LinesEndedByACarriageReturnAlone) {
  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> files = {
      {"m.obj",
       "# tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n"
       "f 2 3 4\n"},
      {"m.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"},
      {"m.stl",
       "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
       "vertex 0 1 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
       "vertex 1 0 0\nvertex 0 0 1\nendloop\nendfacet\nendsolid t\n"}};
  for (const auto& [name, text] : files) {
    SCOPED_TRACE(name);
    write_bytes(dir / name, text);
    const Mesh lf = read_mesh(dir / name);
    ASSERT_FALSE(lf.triangles.empty());
    std::string cr = text;
    std::replace(cr.begin(), cr.end(), '\n', '\r');
    write_bytes(dir / name, cr);
    expect_same_mesh(lf, read_mesh(dir / name));
  }
  // Lines are counted at lone carriage returns too.
  write_bytes(dir / "bad.obj", "v 0 0 0\rv 1 0 0\r\rv 0 x 0\r");
  EXPECT_NE(error_of(dir / "bad.obj").find("line 4: bad number 'x'"), std::string::npos)
      << error_of(dir / "bad.obj");
}

// `fo` (the face keyword of OBJ's first versions) is a face, a comment may follow the last index
// without a space, and a `\` that ends a line continues the statement on the next: `fo` faces
// were skipped (exit 0), `3#` and `\` were bad indices.
TEST(MeshReader, ObjOldFaceKeywordCommentsAndContinuations) {
  TempDir dir;
  write_bytes(dir / "o.obj",
              "v 0 0 0\nv 1 0 0\nv 0 1 0 # top\nv 0 0 \\\r\n1#apex\nfo 1 3 2\n"
              "f 1 2 4# side\nf 1 \\\n  \\\n4 3#\n");
  const Mesh m = read_mesh(dir / "o.obj");
  EXPECT_TRUE(same_bits(m.positions, {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}}));
  write_bytes(dir / "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 \\ 2 3\n");
  EXPECT_NE(error_of(dir / "bad.obj").find("line 4: '\\' before '2'"), std::string::npos)
      << error_of(dir / "bad.obj");
}

// Stanford's `tristrips` element: strips ended by -1, every other triangle turned round so all
// face one way, triangles with a corner twice (the joins) left out. It was skipped (no faces,
// exit 0).
TEST(MeshReader, PlyTriangleStrips) {
  TempDir dir;
  // A 3x2 grid of vertices: 0 1 2 / 3 4 5. One strip 0 3 1 4 2 5, its four triangles facing -z;
  // then two runs, the second with corners repeated as joins do.
  const std::string head =
      "element vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
      "element tristrips 2\nproperty list int int vertex_indices\nend_header\n";
  const std::string ascii = "ply\nformat ascii 1.0\n" + head +
                            "0 0 0\n1 0 0\n2 0 0\n0 1 0\n1 1 0\n2 1 0\n"
                            "6 0 3 1 4 2 5\n9 0 1 4 -1 2 2 5 4 4\n";
  write_bytes(dir / "a.ply", ascii);
  std::string binary = "ply\nformat binary_big_endian 1.0\n" + head;
  for (int v = 0; v < 6; ++v) {
    put_be(binary, static_cast<float>(v % 3));
    put_be(binary, static_cast<float>(v / 3));
    put_be(binary, 0.0f);
  }
  for (const std::vector<std::int32_t>& strip :
       {std::vector<std::int32_t>{0, 3, 1, 4, 2, 5}, {0, 1, 4, -1, 2, 2, 5, 4, 4}}) {
    put_be(binary, static_cast<std::int32_t>(strip.size()));
    for (std::int32_t c : strip) put_be(binary, c);
  }
  write_bytes(dir / "b.ply", binary);
  for (const char* name : {"a.ply", "b.ply"}) {
    SCOPED_TRACE(name);
    const Mesh m = read_mesh(dir / name);
    ASSERT_EQ(m.positions.size(), 6u);
    EXPECT_EQ(m.triangles,
              (std::vector<Tri>{{0, 3, 1}, {1, 3, 4}, {1, 4, 2}, {2, 4, 5}, {0, 1, 4}, {5, 2, 4}}));
  }
  std::string bad = ascii;
  bad.replace(bad.find("-1"), 2, "-2");
  write_bytes(dir / "bad.ply", bad);
  EXPECT_NE(error_of(dir / "bad.ply").find("strip 1 references vertex -2 but there are 6"),
            std::string::npos)
      << error_of(dir / "bad.ply");
}

// A mesh under element names this reader does not read is refused, not skipped: `Vertex` and
// `Face` (PLY's names are case-sensitive) gave an empty mesh, exit 0.
TEST(MeshReaderErrors, PlyMeshUnderOtherNamesIsRefused) {
  TempDir dir;
  const std::string body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  auto ply = [](const std::string& vertex, const std::string& face) {
    return "ply\nformat ascii 1.0\nelement " + vertex +
           " 3\nproperty float x\nproperty float y\nproperty float z\nelement " + face +
           " 1\nproperty list uchar int vertex_indices\nend_header\n";
  };
  write_bytes(dir / "v.ply", ply("Vertex", "face") + body);
  EXPECT_NE(error_of(dir / "v.ply")
                .find("element 'Vertex' has x, y and z, but vertices are read "
                      "from the element named 'vertex'"),
            std::string::npos)
      << error_of(dir / "v.ply");
  write_bytes(dir / "f.ply", ply("vertex", "polygon") + body);
  EXPECT_NE(error_of(dir / "f.ply")
                .find("element 'polygon' lists vertex_indices, but faces are "
                      "read from elements named 'face' or 'tristrips'"),
            std::string::npos)
      << error_of(dir / "f.ply");
  // Another element with x, y and z beside the vertices (a camera's, say) is skipped.
  std::string cam = ply("vertex", "face");
  cam.insert(cam.find("element vertex"),
             "element camera 1\nproperty float x\nproperty float y\nproperty float z\n");
  write_bytes(dir / "cam.ply", cam + "5 5 5\n" + body);
  EXPECT_EQ(read_mesh(dir / "cam.ply").triangles, (std::vector<Tri>{{0, 1, 2}}));
}

// An ASCII PLY record is one line: a header that names fewer properties than the lines hold, or
// more, put the values in the wrong places (three lines of `0 0 0 1` read as four vertices of
// three, exit 0).
TEST(MeshReaderErrors, AsciiPlyRecordsAreLines) {
  TempDir dir;
  auto ply = [](int props, const std::string& body) {
    std::string s = "ply\nformat ascii 1.0\nelement vertex 4\n";
    const char* names[] = {"x", "y", "z", "nx", "ny", "nz"};
    for (int i = 0; i < props; ++i) s += std::string("property float ") + names[i] + "\n";
    return s + "element face 1\nproperty list uchar int vertex_indices\nend_header\n" + body;
  };
  write_bytes(dir / "more.ply", ply(3, "0 0 0 1\n0 0 0 1\n0 0 0 1\n3 0 1 2\n"));
  EXPECT_NE(error_of(dir / "more.ply")
                .find("line 10: vertex 0 has more values than the header's "
                      "properties for it ('1' is left over)"),
            std::string::npos)
      << error_of(dir / "more.ply");
  // Six properties over lines of three: the totals agree, the normals were the next positions.
  write_bytes(dir / "fewer.ply",
              ply(6, "0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 0\n1 0 1\n0 1 1\n1 1 1\n3 0 1 2\n"));
  EXPECT_NE(error_of(dir / "fewer.ply")
                .find("line 13: vertex 0 has fewer values than the "
                      "header's properties for it"),
            std::string::npos)
      << error_of(dir / "fewer.ply");
  write_bytes(dir / "face.ply", ply(3, "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2 3\n"));
  EXPECT_NE(error_of(dir / "face.ply").find("line 14: face 0 has more values"), std::string::npos)
      << error_of(dir / "face.ply");
  // Blank lines between records and spaces at the ends of lines are no values.
  write_bytes(dir / "blank.ply", ply(3, "0 0 0 \n\n1 0 0\t\n0 1 0\n0 0 1\n\n3 0 1 2 \n"));
  EXPECT_EQ(read_mesh(dir / "blank.ply").triangles, (std::vector<Tri>{{0, 1, 2}}));
}

// Many writers leave out an OFF's edge count, which nothing reads (the first vertex's x was
// taken for it, and the file failed far on: "file ends in face 3").
TEST(MeshReader, OffWithoutTheEdgeCount) {
  TempDir dir;
  write_bytes(dir / "e.off", "OFF\n3 1\n0.5 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  const Mesh m = read_mesh(dir / "e.off");
  EXPECT_TRUE(same_bits(m.positions, {{0.5f, 0, 0}, {1, 0, 0}, {0, 1, 0}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
  write_bytes(dir / "one.off", "OFF\n3\n1 0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_NE(error_of(dir / "one.off").find("line 2: expected the vertex and face counts"),
            std::string::npos)
      << error_of(dir / "one.off");
}

// A vertex property named twice, whichever: the streamed reader (render's) leaves the file to the
// whole one, which refuses it (it took a second `quality`, and drew the mesh).
TEST(MeshReader, APropertyTwiceIsNotStreamed) {
  TempDir dir;
  for (const char* name : {"x", "quality"}) {
    SCOPED_TRACE(name);
    std::string ply =
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        "property float y\nproperty float z\nproperty float quality\nproperty float " +
        std::string(name) +
        "\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n";
    const float corners[3][5] = {{0, 0, 0, 9, 9}, {1, 0, 0, 9, 9}, {0, 1, 0, 9, 9}};
    ply.append(reinterpret_cast<const char*>(corners), sizeof(corners));
    const std::uint32_t face[3] = {0, 1, 2};
    ply += '\3';
    ply.append(reinterpret_cast<const char*>(face), sizeof(face));
    write_bytes(dir / "twice.ply", ply);
    EXPECT_FALSE(PlyFaceStream::open(dir / "twice.ply").has_value());
    EXPECT_NE(error_of(dir / "twice.ply").find("has a second property"), std::string::npos);
  }
}

// A PLY through a FIFO (any file whose size is unknown) is read whole, its counts checked
// against what came: the streamed reader sized 30,000,000 vertices (360 MB) from a 160-byte
// file's header before it found them missing.
TEST(MeshReader, APlyThroughAFifoIsReadWhole) {
  TempDir dir;
  const fs::path fifo = dir / "m.ply";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 30000000\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n" +
      std::string(36, '\0');
  std::thread writer([&] { std::ofstream(fifo, std::ios::binary) << bytes; });
  std::string streamed = "nothing";
  try {
    if (PlyFaceStream::open(fifo)) streamed = "a stream";
  } catch (const std::exception& e) {
    streamed = e.what();
  }
  if (streamed != "nothing") {
    writer.join();  // it has written: the stream read the FIFO
    FAIL() << "the FIFO was opened as a stream, giving " << streamed;
  }
  const std::string error = error_of(fifo);  // once: a second read would wait for a writer
  writer.join();
  EXPECT_NE(error.find("declares 30000000 records but the file has only 36 bytes left"),
            std::string::npos)
      << error;
}

TEST(MeshReaderErrors, MessagesNameFileAndProblem) {
  TempDir dir;
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 7\n";
  write_bytes(dir / "x.ply", ply);
  EXPECT_EQ(error_of(dir / "x.ply"),
            (dir / "x.ply").string() + ": face 1 references vertex 7 but there are 3 vertices");

  write_bytes(dir / "x.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n");
  EXPECT_EQ(error_of(dir / "x.obj"),
            (dir / "x.obj").string() + ": face 1 references vertex 9 but there are 3 vertices");

  write_bytes(dir / "x.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  EXPECT_EQ(error_of(dir / "x.off"),
            (dir / "x.off").string() + ": face 0 references vertex 3 but there are 3 vertices");

  write_bytes(dir / "neg.obj", "v 0 0 0\nf -1 -2 -3\n");
  EXPECT_NE(error_of(dir / "neg.obj").find("line 2"), std::string::npos);

  write_bytes(dir / "bad.obj", "v 0 zero 0\n");
  EXPECT_NE(error_of(dir / "bad.obj").find("bad number 'zero'"), std::string::npos);

  write_bytes(dir / "two.ply",
              "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
              "end_header\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
  EXPECT_NE(error_of(dir / "two.ply").find("face 0 has 2 corners"), std::string::npos);

  write_bytes(dir / "nox.ply",
              "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nend_header\n0\n");
  EXPECT_NE(error_of(dir / "nox.ply").find("no x, y and z"), std::string::npos);

  write_bytes(dir / "fmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n");
  EXPECT_NE(error_of(dir / "fmt.ply").find("unknown format 'binary_middle_endian'"),
            std::string::npos);

  write_bytes(dir / "e.ply", "");
  EXPECT_EQ(error_of(dir / "e.ply"), (dir / "e.ply").string() + ": empty file");
}

TEST(MeshReaderErrors, HugeCountsAreRejectedBeforeAllocating) {
  TempDir dir;
  write_bytes(dir / "v.ply",
              "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000000\n"
              "property float x\nproperty float y\nproperty float z\nend_header\n0123456789ab");
  EXPECT_NE(error_of(dir / "v.ply").find("declares 4000000000000 records"), std::string::npos);
  write_bytes(dir / "f.ply",
              "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n"
              "property float y\nproperty float z\nelement face 1\n"
              "property list uint uint vertex_indices\nend_header\n\xff\xff\xff\xff");
  EXPECT_NE(error_of(dir / "f.ply").find("file ends in face 0"), std::string::npos);
  write_bytes(dir / "o.off", "OFF\n999999999999 999999999 0\n0 0 0\n");
  EXPECT_NE(error_of(dir / "o.off").find("declares"), std::string::npos);
  std::string stl(84, '\0');
  stl[80] = stl[81] = stl[82] = stl[83] = '\xff';
  write_bytes(dir / "s.stl", stl);
  EXPECT_NE(error_of(dir / "s.stl").find("4294967295 triangles"), std::string::npos);
}

// Counts that say less than the file holds: an error, not the rest dropped without a word (a
// binary STL whose header says 1 of its 4 triangles read as 1 triangle with exit 0).
TEST(MeshReaderErrors, DataPastTheCountsIsRefused) {
  TempDir dir;
  std::string stl(80, '\0');
  const std::uint32_t one = 1;
  stl.append(reinterpret_cast<const char*>(&one), 4);
  for (int t = 0; t < 4; ++t) {
    const float v[12] = {0, 0, 1, 0, 0, 0, 1, 0, 0, 0, static_cast<float>(t + 1), 0};
    stl.append(reinterpret_cast<const char*>(v), sizeof v);
    stl.append(2, '\0');
  }
  write_bytes(dir / "count.stl", stl);
  EXPECT_NE(
      error_of(dir / "count.stl").find("header says 1 triangles (134 bytes) but the file has 284"),
      std::string::npos)
      << error_of(dir / "count.stl");
  // A binary STL whose header starts with "solid" and whose size is off is named as binary.
  std::string solid = stl;
  solid.replace(0, 5, "solid");
  write_bytes(dir / "solid.stl", solid);
  EXPECT_NE(error_of(dir / "solid.stl").find("binary STL header says 1 triangles"),
            std::string::npos)
      << error_of(dir / "solid.stl");
  // An ASCII STL with a stray NUL byte is named as what it looks like too, not only as binary.
  write_bytes(dir / "nul.stl",
              "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
              "vertex 0 1 0\nendloop\nendfacet\nendsolid s\n" +
                  std::string(1, '\0'));
  EXPECT_NE(error_of(dir / "nul.stl")
                .find("; it begins with 'solid' as ASCII STL does, but holds "
                      "a NUL byte (at offset 105), which text does not"),
            std::string::npos)
      << error_of(dir / "nul.stl");
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  write_bytes(dir / "more.ply", head + "3 2 1 0\n");
  EXPECT_NE(error_of(dir / "more.ply").find("line 14: '3' after the last element's records"),
            std::string::npos)
      << error_of(dir / "more.ply");
  write_bytes(dir / "blank.ply", head + "\n\n");
  EXPECT_EQ(read_mesh(dir / "blank.ply").triangles.size(), 1u);
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}};
  write_mesh(m, dir / "bin.ply", {.format = MeshFormat::Ply});
  std::ifstream bin(dir / "bin.ply", std::ios::binary);
  const std::string bin_bytes((std::istreambuf_iterator<char>(bin)),
                              std::istreambuf_iterator<char>());
  write_bytes(dir / "more_bin.ply", bin_bytes + std::string(13, '\0'));
  EXPECT_NE(error_of(dir / "more_bin.ply").find("13 bytes after the last element's records"),
            std::string::npos)
      << error_of(dir / "more_bin.ply");
  write_bytes(dir / "more.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 2 1 0\n# fine\n");
  EXPECT_NE(error_of(dir / "more.off").find("after the last face (the counts line says 1 faces)"),
            std::string::npos)
      << error_of(dir / "more.off");
  write_bytes(dir / "comment.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n# a comment\n");
  EXPECT_EQ(read_mesh(dir / "comment.off").triangles.size(), 1u);
}

TEST(MeshReaderErrors, MissingFileIsIoError) {
  TempDir dir;
  EXPECT_THROW(read_mesh(dir / "absent.ply"), IoError);
  EXPECT_THROW(read_mesh(dir / "absent.xyz"), InputError);
}

// Reading must end in a mesh or an InputError; anything else (another exception, a crash, a
// sanitizer report) fails.
void expect_ok_or_input_error(const fs::path& path, const std::string& what) {
  try {
    read_mesh(path);
  } catch (const InputError&) {
  } catch (const std::exception& e) {
    ADD_FAILURE() << what << ": unexpected " << e.what();
  }
}

struct Sample {
  std::string name;
  MeshWriteOptions options;
  bool every_truncation_fails;  // binary layouts have no valid shorter prefix
};

std::vector<Sample> samples() {
  MeshWriteOptions ascii;
  ascii.ascii = true;
  return {{"s.ply", {}, true},
          {"a.ply", ascii, false},
          {"s.obj", {}, false},
          {"s.off", {}, false},
          {"s.stl", {}, true}};
}

TEST(MeshReaderErrors, EveryTruncation) {
  TempDir dir;
  for (const Sample& sample : samples()) {
    SCOPED_TRACE(sample.name);
    write_mesh(small_mesh(true, true), dir / sample.name, sample.options);
    const std::string full = read_bytes(dir / sample.name);
    const fs::path cut = dir / ("cut" + fs::path(sample.name).extension().string());
    for (std::size_t n = 0; n < full.size(); ++n) {
      write_bytes(cut, full.substr(0, n));
      if (sample.every_truncation_fails) {
        EXPECT_THROW(read_mesh(cut), InputError) << "length " << n;
      } else {
        expect_ok_or_input_error(cut, "length " + std::to_string(n));
      }
    }
  }
}

TEST(MeshReaderErrors, MutatedAndGarbageBytes) {
  TempDir dir;
  std::mt19937 rng(7);
  const char replacements[] = {'\0', '\xff', '-', '9', ' ', '\n', '/', 'e', '\x80'};
  for (const Sample& sample : samples()) {
    SCOPED_TRACE(sample.name);
    write_mesh(small_mesh(true, true), dir / sample.name, sample.options);
    const std::string full = read_bytes(dir / sample.name);
    const fs::path bad = dir / ("bad" + fs::path(sample.name).extension().string());
    for (std::size_t i = 0; i < full.size(); ++i) {
      for (char c : replacements) {
        std::string mutated = full;
        mutated[i] = c;
        write_bytes(bad, mutated);
        expect_ok_or_input_error(bad, "byte " + std::to_string(i));
      }
    }
    // Random tails after a valid beginning, and pure noise.
    for (int trial = 0; trial < 200; ++trial) {
      std::string noisy = full.substr(0, rng() % full.size());
      const std::size_t extra = rng() % 300;
      for (std::size_t k = 0; k < extra; ++k) noisy += static_cast<char>(rng());
      write_bytes(bad, noisy);
      expect_ok_or_input_error(bad, "noise trial " + std::to_string(trial));
    }
  }
}

TEST(MeshWriterErrors, MissingDirectory) {
  TempDir dir;
  const fs::path target = dir / "no-such-dir" / "m.ply";
  try {
    write_mesh(small_mesh(false, false), target);
    ADD_FAILURE() << "no IoError";
  } catch (const IoError& e) {
    EXPECT_EQ(std::string(e.what()), "cannot write " + target.string() + ": folder " +
                                         (dir / "no-such-dir").string() + " does not exist");
  }
  EXPECT_FALSE(fs::exists(target));
  EXPECT_TRUE(dir.entries().empty());
}

TEST(MeshWriterErrors, BadIndexWritesNothing) {
  TempDir dir;
  Mesh m = small_mesh(false, false);
  m.triangles.push_back({0, 1, 5});
  EXPECT_THROW(write_mesh(m, dir / "m.ply"), InputError);
  Mesh n = small_mesh(false, false);
  n.normals.resize(2);
  EXPECT_THROW(write_mesh(n, dir / "m.obj"), InputError);
  EXPECT_TRUE(dir.entries().empty());
}

// Simulates a full disk with the file size limit: writes past it fail with EFBIG.
TEST(MeshWriterErrors, FailedWriteKeepsPreviousTarget) {
  TempDir dir;
  const fs::path target = dir / "m.ply";
  write_bytes(target, "previous content");
  const Mesh big = big_mesh(true, false);

  struct sigaction ignore {
  }, old{};
  ignore.sa_handler = SIG_IGN;
  ASSERT_EQ(::sigaction(SIGXFSZ, &ignore, &old), 0);
  rlimit saved{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
  rlimit limited = saved;
  limited.rlim_cur = 64 * 1024;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &limited), 0);
  bool threw = false;
  std::string message;
  try {
    write_mesh(big, target);
  } catch (const IoError& e) {
    threw = true;
    message = e.what();
  }
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &saved), 0);
  ASSERT_EQ(::sigaction(SIGXFSZ, &old, nullptr), 0);

  EXPECT_TRUE(threw);
  EXPECT_EQ(message.rfind("cannot write " + target.string() + ": ", 0), 0u) << message;
  EXPECT_EQ(read_bytes(target), "previous content");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"m.ply"});
}

TEST(AtomicFile, UncommittedLeavesNothing) {
  TempDir dir;
  const fs::path target = dir / "t.bin";
  write_bytes(target, "old");
  {
    AtomicFile f(target);
    f.write("new data", 8);
    (void)f.temp_path();                  // named, where it had no name yet
    EXPECT_EQ(dir.entries().size(), 2u);  // the target and the temporary beside it
  }
  EXPECT_EQ(read_bytes(target), "old");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"t.bin"});
}

TEST(AtomicFile, CommitReplacesTarget) {
  TempDir dir;
  const fs::path target = dir / "t.bin";
  write_bytes(target, "old");
  AtomicFile f(target);
  f.write("new", 3);
  std::fputs(" data", f.stream());
  EXPECT_EQ(read_bytes(target), "old");
  f.commit();
  EXPECT_EQ(read_bytes(target), "new data");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"t.bin"});
  EXPECT_THROW(f.write("x", 1), IoError);
}

// A writer that places its records with write_at() needs no large stdio buffer (out of core it
// sat on freed pages that the next arrays then could not reuse: docs/tiler.md); a streamed one
// keeps its 4 MiB. Both write the same bytes.
TEST(AtomicFile, APositionedWriterTakesNoLargeBuffer) {
  TempDir dir;
  for (const auto writes : {AtomicFile::Writes::Streamed, AtomicFile::Writes::Positioned}) {
    const bool positioned = writes == AtomicFile::Writes::Positioned;
    const fs::path target = dir / (positioned ? "positioned.bin" : "streamed.bin");
    AtomicFile f(target, writes);
    f.write("head", 4);
    const std::size_t buffer = __fbufsize(f.stream());
    if (positioned)
      EXPECT_LE(buffer, std::size_t{64} << 10);
    else
      EXPECT_EQ(buffer, std::size_t{4} << 20);
    f.write_at(8, "tail", 4);
    f.write_at(4, "body", 4);
    f.commit();
    EXPECT_EQ(read_bytes(target), "headbodytail") << target;
  }
}

TEST(AtomicFile, FailedRenameRemovesTemporary) {
  TempDir dir;
  // A non-empty directory, appearing after the file was opened, cannot be replaced by a file.
  const fs::path target = dir / "occupied";
  AtomicFile f(target);
  fs::create_directories(target / "inside");
  f.write("x", 1);
  EXPECT_THROW(f.commit(), IoError);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"occupied"});
  EXPECT_TRUE(fs::is_directory(target / "inside"));
}

TEST(AtomicFile, WhatEachKindOfPathIs) {
  TempDir dir;
  using Kind = OutputTarget::Kind;
  EXPECT_EQ(resolve_output(dir / "new.ply").kind, Kind::NewFile);
  { std::ofstream(dir / "file.ply") << "x"; }
  EXPECT_EQ(resolve_output(dir / "file.ply").kind, Kind::RegularFile);
  // Links are followed link by link, relative ones from their own folder.
  fs::create_directories(dir / "sub");
  fs::create_symlink("../file.ply", dir / "sub" / "up.ply");
  fs::create_symlink("sub/up.ply", dir / "chain.ply");
  const OutputTarget chain = resolve_output(dir / "chain.ply");
  EXPECT_EQ(chain.kind, Kind::RegularFile);
  EXPECT_EQ(fs::canonical(chain.path), fs::canonical(dir / "file.ply"));
  fs::create_symlink("/proc/self/fd/2", dir / "err.txt");
  const OutputTarget err = resolve_output(dir / "err.txt");
  EXPECT_EQ(err.kind, Kind::Descriptor);
  EXPECT_EQ(err.fd, 2);
  EXPECT_TRUE(err.in_place());
  ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0644), 0);
  EXPECT_EQ(resolve_output(dir / "fifo").kind, Kind::Device);
  // Positioned writes: only a regular file or a new path.
  EXPECT_NO_THROW(check_output(dir / "file.ply", true));
  EXPECT_NO_THROW(check_output(dir / "new.ply", true));
  EXPECT_THROW(check_output(dir / "fifo", true), IoError);
  EXPECT_THROW(check_output(dir / "err.txt", true), IoError);
  fs::create_symlink("loop2", dir / "loop1");
  fs::create_symlink("loop1", dir / "loop2");
  const auto message = [](const fs::path& p) {
    try {
      resolve_output(p);
    } catch (const IoError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_EQ(message(dir / "loop1"),
            "cannot write " + (dir / "loop1").string() + ": Too many levels of symbolic links");
  EXPECT_EQ(message(dir / "sub"), "cannot write " + (dir / "sub").string() + ": it is a directory");
  EXPECT_EQ(message(dir / "file.ply" / "x.ply"),
            "cannot write " + (dir / "file.ply" / "x.ply").string() + ": Not a directory");
  // Nothing was written or created by asking.
  EXPECT_FALSE(fs::exists(dir / "new.ply"));
  EXPECT_EQ(fs::file_size(dir / "file.ply"), 1u);
}

TEST(AtomicFile, AFifoIsWrittenInPlace) {
  TempDir dir;
  const fs::path fifo = dir / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  std::string got;
  std::thread reader([&] {
    std::ifstream in(fifo, std::ios::binary);
    got.assign(std::istreambuf_iterator<char>(in), {});
  });
  try {
    AtomicFile f(fifo);
    EXPECT_TRUE(f.in_place());
    f.write("hello", 5);
    EXPECT_THROW(f.write_at(0, "x", 1), IoError);
    f.commit();
  } catch (const std::exception& e) {
    ADD_FAILURE() << e.what();
  }
  // A writer of our own releases the reader if the FIFO was never opened.
  if (const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK); fd >= 0) ::close(fd);
  reader.join();
  EXPECT_EQ(got, "hello");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"fifo"});
  EXPECT_EQ(fs::status(fifo).type(), fs::file_type::fifo);
}

// Whether files without a name can be made in `dir` (O_TMPFILE: ext4, XFS, Btrfs, tmpfs; not
// every network or overlay file system).
bool takes_unnamed_files(const std::filesystem::path& dir) {
  const int fd = ::open(dir.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0600);
  if (fd < 0) return false;
  ::close(fd);
  return true;
}

// Until commit() the data has no name in the folder: a process killed outright (SIGKILL) leaves
// nothing. It gets one when asked for it (MPI ranks open it by name), and commit() gives it the
// target's.
TEST(AtomicFile, AnUncommittedFileHasNoNameUntilAskedForOne) {
  TempDir dir;
  if (!takes_unnamed_files(dir.path()))
    GTEST_SKIP() << dir.path() << " cannot hold files without a name (no O_TMPFILE)";
  AtomicFile a(dir / "a.bin");
  a.write("abc", 3);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{});
  const std::filesystem::path named = a.temp_path();
  EXPECT_EQ(dir.entries(), std::vector<std::string>{named.filename().string()});
  a.write("d", 1);
  a.commit();
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"a.bin"});
  std::ifstream in(dir / "a.bin", std::ios::binary);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "abcd");
  // Never named: committed straight to the target; discarded without a trace.
  {
    AtomicFile b(dir / "b.bin");
    b.write("b", 1);
    b.commit();
    AtomicFile c(dir / "c.bin");
    c.write("c", 1);
  }
  EXPECT_EQ(dir.entries(), (std::vector<std::string>{"a.bin", "b.bin"}));
}

TEST(AtomicFile, SignalCleanupRemovesTemporaries) {
  TempDir dir;
  {
    AtomicFile a(dir / "a.bin");
    AtomicFile b(dir / "b.bin");
    a.write("a", 1);
    // Named, as MPI ranks' shared temporaries are (unnamed ones need no cleanup).
    (void)a.temp_path();
    (void)b.temp_path();
    EXPECT_EQ(dir.entries().size(), 2u);
    remove_pending_temporaries();
    EXPECT_TRUE(dir.entries().empty());
    // The temporary is gone, so the rename cannot happen: an error, not a half-written target.
    EXPECT_THROW(a.commit(), IoError);
  }
  EXPECT_TRUE(dir.entries().empty());
  // Slots are reused after release: many files in sequence keep working.
  for (int i = 0; i < 200; ++i) {
    AtomicFile f(dir / "seq.bin");
    f.write(&i, sizeof(i));
    f.commit();
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"seq.bin"});
}

}  // namespace
}  // namespace isotile
