#include "tests/fuzz/fuzz_seeds.h"

#include <openvdb/openvdb.h>
#include <teem/nrrd.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <mutex>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include "core/mesh/mesh_io.h"
#include "core/volume/itk_reader.h"
#include "core/volume/scalar_type.h"
#include "tests/dicom_bytes.h"
#include "tests/fuzz/fuzz_targets.h"

namespace isotile::fuzz {

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

// A scratch directory for the writers, removed on destruction.
class ScratchDir {
 public:
  ScratchDir() {
    static std::atomic<int> counter{0};
    path_ = fs::temp_directory_path() /
            ("isotile_fuzz_seeds_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  fs::path operator/(const std::string& name) const { return path_ / name; }

 private:
  fs::path path_;
};

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("fuzz seeds: cannot read " + path.string());
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

Bytes with_selector(std::uint8_t selector, std::string_view body) {
  Bytes b;
  b.reserve(body.size() + 1);
  b.push_back(selector);
  b.insert(b.end(), body.begin(), body.end());
  return b;
}

template <class T>
void put_be(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::little) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

// gzip format in memory (windowBits 15 + 16).
std::string gzip(std::string_view data) {
  z_stream z{};
  if (deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    throw std::runtime_error("fuzz seeds: deflateInit2 failed");
  std::string out(deflateBound(&z, static_cast<uLong>(data.size())) + 32, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(data.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  const int rc = deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  if (rc != Z_STREAM_END) throw std::runtime_error("fuzz seeds: deflate failed");
  return out;
}

// ---------------------------------------------------------------------------------------------
// Meshes

Mesh seed_mesh(bool normals, bool quads) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0.5f, 0.5f, 1}, {-2.5f, 1e-3f, 7}};
  m.triangles = {{0, 1, 4}, {1, 2, 4}, {2, 3, 4}, {3, 0, 4}, {0, 4, 5}};
  if (quads)
    m.quads = {{0, 3, 2, 1}};
  else
    m.triangles.insert(m.triangles.end(), {{0, 2, 1}, {0, 3, 2}});
  if (normals) {
    for (std::size_t i = 0; i < m.positions.size(); ++i) m.normals.push_back({0, 0.6f, 0.8f});
  }
  return m;
}

std::string ply_big_endian() {
  std::string s =
      "ply\nformat binary_big_endian 1.0\ncomment doubles, skipped scalars and lists\n"
      "element vertex 4\nproperty double x\nproperty uchar red\nproperty double y\n"
      "property double z\nproperty float nx\nproperty float ny\nproperty float nz\n"
      "property list uchar int16 extra\n"
      "element material 2\nproperty float shininess\n"
      "element face 3\nproperty int flags\nproperty list int uint vertex_index\n"
      "end_header\n";
  const double xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.5}};
  for (int v = 0; v < 4; ++v) {
    put_be(s, xyz[v][0]);
    put_be(s, std::uint8_t{200});
    put_be(s, xyz[v][1]);
    put_be(s, xyz[v][2]);
    for (float n : {0.0f, 0.0f, 1.0f}) put_be(s, n);
    put_be(s, static_cast<std::uint8_t>(v % 3));
    for (int k = 0; k < v % 3; ++k) put_be(s, std::int16_t{-1});
  }
  put_be(s, 1.5f);
  put_be(s, 2.5f);
  for (const std::vector<std::uint32_t>& face :
       {std::vector<std::uint32_t>{0, 1, 2}, std::vector<std::uint32_t>{0, 1, 2, 3},
        std::vector<std::uint32_t>{3, 2, 1, 0, 1}}) {
    put_be(s, std::int32_t{-7});
    put_be(s, static_cast<std::int32_t>(face.size()));
    for (std::uint32_t c : face) put_be(s, c);
  }
  return s;
}

// A binary little-endian PLY with integer coordinates and ushort list counts.
std::string ply_little_endian_ints() {
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty short x\n"
      "property int y\nproperty uchar z\nelement face 1\n"
      "property list ushort int vertex_indices\nend_header\n";
  auto put_le = [&](auto v) {
    char b[sizeof(v)];
    std::memcpy(b, &v, sizeof(v));
    if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(v));
    s.append(b, sizeof(v));
  };
  const int xyz[3][3] = {{0, 0, 0}, {-3, 70000, 255}, {1, 2, 3}};
  for (const auto& p : xyz) {
    put_le(static_cast<std::int16_t>(p[0]));
    put_le(static_cast<std::int32_t>(p[1]));
    put_le(static_cast<std::uint8_t>(p[2]));
  }
  put_le(std::uint16_t{3});
  for (std::int32_t c : {2, 0, 1}) put_le(c);
  return s;
}

}  // namespace

std::vector<Seed> mesh_seeds() {
  enum : std::uint8_t { kPly = 0, kObj = 1, kOff = 2, kStl = 3, kUpper = 4 };
  std::vector<Seed> seeds;
  ScratchDir dir;
  auto written = [&](const std::string& name, std::uint8_t selector, const Mesh& mesh,
                     MeshWriteOptions options = {}) {
    static constexpr const char* kExt[4] = {".ply", ".obj", ".off", ".stl"};
    const fs::path path = dir / (name + kExt[selector & 3]);
    write_mesh(mesh, path, options);
    seeds.push_back({name, with_selector(selector, read_text(path))});
  };
  MeshWriteOptions ascii;
  ascii.ascii = true;
  written("ply_binary_normals", kPly, seed_mesh(true, true));
  written("ply_binary", kPly | kUpper, seed_mesh(false, true));
  written("ply_ascii_normals", kPly, seed_mesh(true, true), ascii);
  written("ply_ascii", kPly, seed_mesh(false, false), ascii);
  written("obj_normals", kObj, seed_mesh(true, true));
  written("obj", kObj | kUpper, seed_mesh(false, false));
  written("off", kOff, seed_mesh(false, true));
  written("off_tris", kOff, seed_mesh(true, false));
  written("stl", kStl, seed_mesh(false, true));
  written("stl_upper", kStl | kUpper, seed_mesh(false, false));
  written("stl_empty", kStl, Mesh{});

  auto text = [&](const std::string& name, std::uint8_t selector, std::string_view body,
                  bool readable = true) {
    seeds.push_back({name, with_selector(selector, body), readable});
  };
  text("ply_big_endian", kPly, ply_big_endian());
  text("ply_little_endian_ints", kPly, ply_little_endian_ints());
  text("ply_ascii_hand", kPly,
       "ply\r\nformat ascii 1.0\r\nobj_info made by hand\r\n"
       "element vertex 3\r\n"
       "property int x\r\nproperty float nz\r\nproperty short y\r\nproperty double z\r\n"
       "property float nx\r\nproperty float ny\r\nproperty list uint8 float uv\r\n"
       "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
       "element face 2\r\nproperty list uint8 uint32 vertex_indices\r\nproperty uchar flag\r\n"
       "end_header\r\n"
       "1 1 2 3.5 0 0 2 0.5 0.5\r\n"
       "-4 0.5 -5 0.1 0.6 0.8 0\r\n"
       "0 1 0 0 0 0 1 0.25\r\n"
       "0 1\r\n"
       "3 2 1 0 9\r\n"
       "5 0 1 2 0 1 7\r\n");
  text("ply_doubles", kPly,
       "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\n"
       "property double z\nend_header\n3.4028235e38 -3.4028235e38 0.1\n3.4e38 -3.4e38 1e-50\n");
  text("obj_hand", kObj,
       "# a comment\nmtllib none.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 1 1 0 1.0\n"
       "v 0 1 0 0.5 0.5 0.5\nvt 0 0\nvn 0 0 1\n\nf 1/1/1 2/1/1 3/1/1\n"
       "f -4//-1 -2//-1 -1//-1   # trailing comment\nusemtl x\ns off\nv 0.5 2 0\n"
       "f 1 2 3 4\nf 1/1 2/1 3/1/ 4/1 5/1\ng group\n");
  text("obj_matching_normals", kObj,
       "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n");
  text("off_hand", kOff,
       "COFF 5 3 0\n# colours follow the coordinates\n0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n\n"
       "1 1 0 255 0 0 255\n0 1 0 255 0 0 255\n0.5 2 0 255 0 0 255\n3 0 1 2\n"
       "4 0 1 2 3 0.5 0.5 0.5\n5 0 1 2 3 4\n");
  text("noff_hand", kOff, "NOFF\n3 1 3\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n");
  text("stl_ascii", kStl,
       "solid first\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n"
       "      vertex 1 0 0\n      vertex 0 1 0\n    endloop\n  endfacet\nendsolid first\n"
       "solid second\n  facet normal 0 0 0\n    outer loop\n      vertex 1 0 0\n"
       "      vertex 1 1 -0\n      vertex 0 1 0\n    endloop\n  endfacet\nendsolid second\n");
  text("obj_bad_index", kObj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", false);
  text("ply_too_many_faces", kPly,
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
       "property float z\nelement face 99\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
       false);
  return seeds;
}

// ---------------------------------------------------------------------------------------------
// Raw

std::vector<Seed> raw_seeds() {
  std::vector<Seed> seeds;
  for (int layout = 0; layout < 8; ++layout) {
    for (int t = 0; t < kScalarTypeCount; ++t) {
      for (int gz = 0; gz < 2; ++gz) {
        const auto type = static_cast<ScalarType>(t);
        const bool big = (layout + t + gz) % 2 == 1;
        const RawLayout l = raw_layout(layout, type, gz);
        const std::int64_t n = l.dims[0] * l.dims[1] * l.dims[2];
        std::string data;
        for (std::int64_t i = 0; i < n; ++i) {
          // Values within every type's range, some negative.
          const double v = static_cast<double>((i * 37) % 101) - (t % 2 == 0 ? 50 : 0);
          visit_scalar(type, [&](auto tag) {
            using T = decltype(tag);
            const T x = static_cast<T>(v);
            char b[sizeof(T)];
            std::memcpy(b, &x, sizeof(T));
            if (big == (std::endian::native == std::endian::little)) std::reverse(b, b + sizeof(T));
            data.append(b, sizeof(T));
          });
        }
        const auto selector =
            static_cast<std::uint8_t>(gz | (big ? 2 : 0) | (t << 2) | (layout << 5));
        seeds.push_back({"raw_layout" + std::to_string(layout) + "_" +
                             std::string(scalar_name(type)) + (big ? "_be" : "_le") +
                             (gz ? "_gz" : ""),
                         with_selector(selector, gz ? gzip(data) : data)});
      }
    }
  }
  // Sizes that do not match, and a .gz that is not gzip data.
  seeds.push_back({"raw_short", with_selector(0x20 | (1 << 2), std::string(23, '\x01')), false});
  seeds.push_back({"raw_long", with_selector(0x20 | (1 << 2), std::string(25, '\x01')), false});
  seeds.push_back({"raw_gz_not_gzip", with_selector(0x01, std::string(1, '\x07')), false});
  seeds.push_back(
      {"raw_gz_long", with_selector(0x01 | (1 << 2), gzip(std::string(2, '\x07'))), false});
  seeds.push_back(
      {"raw_nan", with_selector(6 << 2, std::string_view("\x00\x00\xc0\x7f", 4)), false});
  return seeds;
}

// ---------------------------------------------------------------------------------------------
// NRRD

namespace {

struct NrrdSeedSpec {
  std::string name;
  int type = nrrdTypeFloat;
  std::vector<std::size_t> sizes{3, 4, 5};
  const NrrdEncoding* encoding = nrrdEncodingRaw;
  bool detached = false;
  bool spacing = false;
  bool space = false;  // space directions and origin
  bool readable = true;
};

std::string biff_text() {
  char* e = biffGetDone(NRRD);
  std::string s = e ? e : "unknown teem error";
  std::free(e);
  return s;
}

Seed nrrd_seed(const NrrdSeedSpec& spec) {
  std::size_t count = 1;
  for (std::size_t s : spec.sizes) count *= s;
  const std::size_t element = nrrdTypeSize[spec.type];
  std::vector<unsigned char> data(count * element);
  for (std::size_t i = 0; i < count; ++i) {
    const double v = static_cast<double>((i * 37) % 101) - 30;
    switch (spec.type) {
      case nrrdTypeFloat: {
        const float f = static_cast<float>(v) * 0.25f;
        std::memcpy(&data[i * element], &f, element);
        break;
      }
      case nrrdTypeDouble: {
        const double d = v * 0.125;
        std::memcpy(&data[i * element], &d, element);
        break;
      }
      default: {
        // Integers: the low bytes of v, which stay in range for every integer type.
        const auto x = static_cast<std::int64_t>(v < 0 ? -v : v);
        std::memcpy(&data[i * element], &x, element);  // little-endian hosts only, see below
        break;
      }
    }
  }
  static_assert(std::endian::native == std::endian::little, "seed integers assume little-endian");

  ScratchDir dir;
  const fs::path path = dir / (spec.detached ? "seed.nhdr" : "seed.nrrd");
  Nrrd* n = nrrdNew();
  std::string error;
  if (nrrdWrap_nva(n, data.data(), spec.type, static_cast<unsigned>(spec.sizes.size()),
                   spec.sizes.data()) != 0)
    error = biff_text();
  if (error.empty() && spec.spacing) {
    double spacing[NRRD_DIM_MAX] = {0.5, 2, 3.25, 1};
    nrrdAxisInfoSet_nva(n, nrrdAxisInfoSpacing, spacing);
  }
  if (error.empty() && spec.space) {
    if (nrrdSpaceDimensionSet(n, 3) != 0) error = biff_text();
    double dirs[NRRD_DIM_MAX][NRRD_SPACE_DIM_MAX] = {};
    const std::size_t first = spec.sizes.size() - 3;
    for (int a = 0; a < 3; ++a) dirs[first + a][a] = 0.5 + a;
    for (std::size_t a = 0; a < first; ++a)
      for (int d = 0; d < 3; ++d) dirs[a][d] = AIR_NAN;
    nrrdAxisInfoSet_nva(n, nrrdAxisInfoSpaceDirection, dirs);
    const double origin[3] = {-1, 2.5, 10};
    if (error.empty() && nrrdSpaceOriginSet(n, origin) != 0) error = biff_text();
  }
  if (error.empty()) {
    NrrdIoState* nio = nrrdIoStateNew();
    nio->encoding = spec.encoding;
    if (nrrdSave(path.c_str(), n, nio) != 0) error = biff_text();
    nrrdIoStateNix(nio);
  }
  nrrdNix(n);
  if (!error.empty()) throw std::runtime_error("fuzz seeds: nrrdSave " + spec.name + ": " + error);

  if (!spec.detached) return {spec.name, with_selector(0, read_text(path)), spec.readable};

  // Point the header at the name fuzz_nrrd writes the data under, and append the data.
  std::string header = read_text(path);
  const std::size_t at = header.find("data file: ");
  if (at == std::string::npos)
    throw std::runtime_error("fuzz seeds: detached NRRD header without 'data file'");
  const std::size_t eol = header.find('\n', at);
  const std::string data_name = header.substr(at + 11, eol - at - 11);
  header.replace(at, eol - at, "data file: data.bin");
  if (header.empty() || header.back() != '\n') header += '\n';
  return {spec.name, with_selector(1, header + "\n" + read_text(dir / data_name)), spec.readable};
}

}  // namespace

std::vector<Seed> nrrd_seeds() {
  std::vector<NrrdSeedSpec> specs;
  const std::pair<int, const char*> types[] = {
      {nrrdTypeChar, "int8"},     {nrrdTypeUChar, "uint8"},   {nrrdTypeShort, "int16"},
      {nrrdTypeUShort, "uint16"}, {nrrdTypeInt, "int32"},     {nrrdTypeUInt, "uint32"},
      {nrrdTypeFloat, "float32"}, {nrrdTypeDouble, "float64"}};
  for (const auto& [type, name] : types) {
    NrrdSeedSpec s;
    s.name = std::string("nrrd_") + name;
    s.type = type;
    s.spacing = true;
    specs.push_back(s);
  }
  std::vector<std::pair<const NrrdEncoding*, const char*>> encodings = {
      {nrrdEncodingRaw, "raw"}, {nrrdEncodingAscii, "ascii"}, {nrrdEncodingHex, "hex"}};
  if (nrrdEncodingGzip->available()) encodings.push_back({nrrdEncodingGzip, "gzip"});
  if (nrrdEncodingBzip2->available()) encodings.push_back({nrrdEncodingBzip2, "bzip2"});
  for (const auto& [encoding, name] : encodings) {
    for (bool detached : {false, true}) {
      NrrdSeedSpec s;
      s.name = std::string("nrrd_") + name + (detached ? "_detached" : "");
      s.encoding = encoding;
      s.detached = detached;
      s.type = detached ? nrrdTypeUShort : nrrdTypeFloat;
      s.space = !detached;
      specs.push_back(s);
    }
  }
  {
    NrrdSeedSpec s;
    s.name = "nrrd_4d";
    s.sizes = {1, 3, 2, 4};
    s.type = nrrdTypeDouble;
    s.space = true;
    specs.push_back(s);
    s.name = "nrrd_4d_two_components";
    s.sizes = {2, 3, 2, 2};
    s.space = false;
    s.readable = false;
    specs.push_back(s);
    s.name = "nrrd_2d";
    s.sizes = {4, 5};
    specs.push_back(s);
    s.name = "nrrd_llong";
    s.sizes = {2, 2, 2};
    s.type = nrrdTypeLLong;
    specs.push_back(s);
  }
  std::vector<Seed> seeds;
  for (const NrrdSeedSpec& s : specs) seeds.push_back(nrrd_seed(s));

  // Hand edits of what teem wrote: big-endian data, a header with comments and key/values.
  for (Seed s : std::vector<Seed>(seeds.begin(), seeds.begin() + 4)) {
    std::string text(s.bytes.begin() + 1, s.bytes.end());
    const std::size_t at = text.find("endian: little");
    if (at == std::string::npos) continue;
    text.replace(at, 14, "endian: big");
    text.insert(text.find('\n') + 1, "# a comment\nsome key:=some value\n");
    seeds.push_back({s.name + "_big_endian", with_selector(0, text)});
  }
  return seeds;
}

// ---------------------------------------------------------------------------------------------
// OpenVDB

std::vector<Seed> vdb_seeds() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
  std::vector<Seed> seeds;
  ScratchDir dir;
  auto save = [&](const std::string& name, const openvdb::GridPtrVec& grids, bool readable = true,
                  std::optional<std::uint32_t> compression = std::nullopt) {
    const fs::path path = dir / (name + ".vdb");
    openvdb::io::File file(path.string());
    if (compression) file.setCompression(*compression);
    file.write(grids);
    file.close();
    const std::string text = read_text(path);
    seeds.push_back({name, Bytes(text.begin(), text.end()), readable});
  };
  auto float_grid = [](const std::string& name) {
    auto grid = openvdb::FloatGrid::create(0.25f);
    grid->setName(name);
    auto transform = openvdb::math::Transform::createLinearTransform(0.5);
    transform->postTranslate(openvdb::Vec3d(10, 20, 30));
    grid->setTransform(transform);
    auto acc = grid->getAccessor();
    acc.setValueOn(openvdb::Coord(-2, 3, 5), 1.5f);
    acc.setValueOn(openvdb::Coord(1, 4, 5), 2.5f);
    acc.setValueOn(openvdb::Coord(0, 3, 9), -1.0f);
    acc.setValueOff(openvdb::Coord(-1, 4, 6), 9.0f);
    return grid;
  };

  save("vdb_float", {float_grid("density")});
  for (const auto& [name, c] : std::vector<std::pair<std::string, std::uint32_t>>{
           {"none", openvdb::io::COMPRESS_NONE},
           {"zip", openvdb::io::COMPRESS_ZIP},
           {"active_mask", openvdb::io::COMPRESS_ACTIVE_MASK},
           {"zip_active_mask", openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK},
           {"blosc", openvdb::io::COMPRESS_BLOSC}}) {
    save("vdb_float_" + name, {float_grid("density")}, true, c);
  }
  {
    auto grid = openvdb::DoubleGrid::create(-1.0);
    grid->setName("phi");
    openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
    m.setToScale(openvdb::Vec3d(0.5, 2, 1));
    m.setTranslation(openvdb::Vec3d(1, 2, 3));
    try {
      grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
    } catch (const openvdb::Exception&) {
      // A matrix OpenVDB refuses (nearly singular): keep the default transform.
    }
    // A whole leaf's worth becomes a tile; one more voxel sits in a leaf of its own.
    grid->fill(openvdb::CoordBBox(openvdb::Coord(0, 0, 0), openvdb::Coord(7, 7, 7)), 3.0, true);
    grid->tree().setValueOn(openvdb::Coord(9, 1, 2), 0.5);
    save("vdb_double_tile", {grid});
  }
  {
    auto grid = float_grid("half");
    grid->setSaveFloatAsHalf(true);
    save("vdb_float_half", {grid});
  }
  {
    auto ints = openvdb::Int32Grid::create(0);
    ints->setName("labels");
    ints->tree().setValueOn(openvdb::Coord(1, 2, 3), 7);
    save("vdb_int_then_float", {ints, float_grid("density")});
    save("vdb_int_only", {ints}, false);
    save("vdb_repeated_names", {float_grid(""), float_grid("")});
    auto meta = float_grid("meta");
    meta->insertMeta("note", openvdb::StringMetadata("fuzz seed"));
    meta->insertMeta("count", openvdb::Int32Metadata(42));
    meta->insertMeta("scale", openvdb::Vec3DMetadata(openvdb::Vec3d(1, 2, 3)));
    save("vdb_metadata", {meta});
  }
  {
    auto empty = openvdb::FloatGrid::create(0.0f);
    empty->setName("empty");
    save("vdb_no_active_voxels", {empty}, false);
    auto nan = float_grid("nan");
    nan->tree().setValueOn(openvdb::Coord(0, 4, 6), std::numeric_limits<float>::quiet_NaN());
    save("vdb_nan", {nan}, false);
  }
  return seeds;
}

Seed random_vdb_seed(std::uint32_t seed) {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
  std::mt19937 rng(seed);
  // Plain modulo rather than a distribution: the same draws with every standard library.
  auto below = [&](std::uint32_t n) { return rng() % n; };
  auto chance = [&](std::uint32_t percent) { return below(100) < percent; };
  auto value = [&]() -> double {
    switch (below(40)) {
      case 0:
        return std::numeric_limits<double>::quiet_NaN();
      case 1:
        return -std::numeric_limits<double>::infinity();
      case 2:
        return 1e300;  // infinite as a float
      case 3:
        return 7e4;  // infinite as a half
      default:
        return static_cast<double>(static_cast<int>(below(2001)) - 1000) / 8;
    }
  };
  // A point within `extent` of `centre` (per axis), clamped to the coordinate range.
  auto near = [&](const openvdb::Coord& centre, std::int64_t extent) {
    std::int64_t c[3];
    for (int a = 0; a < 3; ++a) {
      const std::int64_t v =
          centre[a] + static_cast<std::int64_t>(below(static_cast<std::uint32_t>(2 * extent + 1))) -
          extent;
      c[a] = std::clamp<std::int64_t>(v, std::numeric_limits<std::int32_t>::min(),
                                      std::numeric_limits<std::int32_t>::max());
    }
    return openvdb::Coord(static_cast<openvdb::Int32>(c[0]), static_cast<openvdb::Int32>(c[1]),
                          static_cast<openvdb::Int32>(c[2]));
  };
  auto coord = [&](std::int64_t extent) { return near(openvdb::Coord(0), extent); };

  auto fill = [&](auto grid) {
    using ValueT = typename std::decay_t<decltype(*grid)>::ValueType;
    auto cast = [](double v) { return static_cast<ValueT>(v); };
    // Up to the whole coordinate range, where bounding-box sizes overflow 32 bits.
    static constexpr std::int64_t kExtents[] = {3, 20, 200, 5000, 1 << 20, 1 << 30};
    const std::int64_t extent = kExtents[below(6)];
    const openvdb::Coord centre = coord(chance(5) ? 1 << 30 : chance(25) ? 100000 : 50);
    auto acc = grid->getAccessor();
    // One draw per statement: the order in which arguments are evaluated varies by compiler.
    for (std::uint32_t n = below(12); n > 0; --n) {
      const openvdb::Coord c = near(centre, chance(80) ? 4 : extent);
      acc.setValueOn(c, cast(chance(95) ? 0.25 * n - 1 : value()));
    }
    for (std::uint32_t n = below(4); n > 0; --n) {
      const openvdb::Coord c = near(centre, 4);
      acc.setValueOff(c, cast(chance(50) ? 2.5 : value()));
    }
    if (chance(10)) {  // a leaf-sized tile
      const openvdb::Coord lo = near(centre, 16) & ~7;
      const ValueT v = cast(value());
      grid->fill(openvdb::CoordBBox(lo, lo.offsetBy(7)), v, chance(80));
    }
    if (chance(3)) {  // an internal-node tile of 128^3 voxels, or a root tile of 4096^3
      const openvdb::Index level = chance(70) ? 2 : 3;
      const ValueT v = cast(chance(80) ? 0.5 : value());
      grid->tree().addTile(level, centre, v, chance(80));
    }
  };

  openvdb::GridPtrVec grids;
  for (std::uint32_t g = chance(75) ? 1 : 2 + below(2); g > 0; --g) {
    openvdb::GridBase::Ptr grid;
    const double background = chance(90) ? 0.0 : value();
    switch (below(10)) {
      case 0:
      case 1:
        grid = openvdb::DoubleGrid::create(background);
        fill(openvdb::gridPtrCast<openvdb::DoubleGrid>(grid));
        break;
      case 2: {
        auto ints = openvdb::Int32Grid::create(0);
        ints->tree().setValueOn(coord(10), 3);
        grid = ints;
        break;
      }
      case 3: {
        auto vecs = openvdb::Vec3SGrid::create(openvdb::Vec3s(0));
        vecs->tree().setValueOn(coord(10), openvdb::Vec3s(1, 2, 3));
        grid = vecs;
        break;
      }
      default: {
        auto floats = openvdb::FloatGrid::create(static_cast<float>(background));
        fill(floats);
        if (chance(20)) floats->setSaveFloatAsHalf(true);
        grid = floats;
        break;
      }
    }
    static constexpr const char* kNames[] = {"density", "", "phi", "density"};
    grid->setName(kNames[below(4)]);
    static constexpr double kScales[] = {1, 0.5, 3, 1e-6, 1e6, 1e-30};
    openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
    if (chance(30)) {
      openvdb::Vec3d scale;
      for (int a = 0; a < 3; ++a) scale[a] = kScales[below(6)];
      m.setToScale(scale);
    } else {
      const double s = kScales[below(6)];
      m.setToScale(openvdb::Vec3d(s, s, s));
    }
    if (chance(20)) m.preRotate(openvdb::math::Z_AXIS, 0.3 * below(10));
    openvdb::Vec3d translation;
    translation[0] = value();
    translation[1] = value();
    translation[2] = chance(95) ? 0.0 : 1e308;
    m.setTranslation(translation);
    try {
      grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
    } catch (const openvdb::Exception&) {
      // A matrix OpenVDB refuses (nearly singular): keep the default transform.
    }
    if (chance(10)) grid->insertMeta("note", openvdb::StringMetadata("random"));
    grids.push_back(grid);
  }

  static constexpr std::uint32_t kCompression[] = {
      openvdb::io::COMPRESS_NONE, openvdb::io::COMPRESS_ZIP, openvdb::io::COMPRESS_ACTIVE_MASK,
      openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK, openvdb::io::COMPRESS_BLOSC};
  static const ScratchDir dir;  // one for all calls: directories cost more than the grids
  const fs::path path = dir / "random.vdb";
  const std::uint32_t compression = kCompression[below(5)];
  auto write = [&] {
    openvdb::io::File file(path.string());
    file.setCompression(compression);
    file.write(grids);
    file.close();
  };
  try {
    write();
  } catch (const openvdb::Exception&) {
    // A transform OpenVDB cannot write (e.g. one it finds singular): use the default ones.
    for (auto& grid : grids) grid->setTransform(openvdb::math::Transform::createLinearTransform());
    write();
  }
  const std::string text = read_text(path);
  return {"vdb_random_" + std::to_string(seed), Bytes(text.begin(), text.end()), true};
}

namespace {

// A multi-frame 8-bit DICOM file (explicit VR little endian), element by element: one file that
// GDCM reads as a volume of `frames` slices (an MR image: GDCM reads the distance between its
// frames from SpacingBetweenSlices; for a secondary capture it reads none, which isotile refuses).
std::string dicom_multiframe(const std::vector<std::uint8_t>& pixels, int columns, int rows,
                             int frames) {
  using testing::dicom::element;
  using testing::dicom::u16;
  const std::string sop_class = "1.2.840.10008.5.1.4.1.1.4", sop = "1.2.826.0.1.3680043.2.1.1";
  const std::string body =
      element(0x0008, 0x0016, "UI", sop_class) + element(0x0008, 0x0018, "UI", sop) +
      element(0x0008, 0x0060, "CS", "MR") + element(0x0018, 0x0088, "DS", "1") +
      element(0x0020, 0x000D, "UI", "1.2.826.0.1.3680043.2.1.2") +
      element(0x0020, 0x000E, "UI", "1.2.826.0.1.3680043.2.1.3") +
      element(0x0020, 0x0013, "IS", "1") + element(0x0020, 0x0032, "DS", "0\\0\\0") +
      element(0x0020, 0x0037, "DS", "1\\0\\0\\0\\1\\0") + element(0x0028, 0x0002, "US", u16(1)) +
      element(0x0028, 0x0004, "CS", "MONOCHROME2") +
      element(0x0028, 0x0008, "IS", std::to_string(frames)) +
      element(0x0028, 0x0010, "US", u16(static_cast<std::uint16_t>(rows))) +
      element(0x0028, 0x0011, "US", u16(static_cast<std::uint16_t>(columns))) +
      element(0x0028, 0x0030, "DS", "1\\1") + element(0x0028, 0x0100, "US", u16(8)) +
      element(0x0028, 0x0101, "US", u16(8)) + element(0x0028, 0x0102, "US", u16(7)) +
      element(0x0028, 0x0103, "US", u16(0)) +
      element(0x7FE0, 0x0010, "OB", std::string(pixels.begin(), pixels.end()));
  return testing::dicom::part10(sop_class, sop, body);
}

}  // namespace

std::vector<Seed> image_seeds() {
  std::vector<Seed> seeds;
  // MRC: a little-endian float map in X, Y, Z order, a big-endian int16 map in another axis
  // order with start fields and an extended header, and a mode 12 map.
  struct Mrc {
    const char* name;
    int mode, map[3], start[3], nsymbt;
    bool big;
    std::uint8_t selector;
  };
  for (const Mrc& m : {Mrc{"mrc_float_xyz", 2, {1, 2, 3}, {0, 0, 0}, 0, false, 0},
                       Mrc{"ccp4_int16_zxy_be", 1, {3, 1, 2}, {-3, 2, 5}, 16, true, 3},
                       Mrc{"mrc_half", 12, {1, 2, 3}, {0, 0, 0}, 0, false, 0},
                       Mrc{"mrc_uint16", 6, {2, 3, 1}, {1, 1, 1}, 0, false, 0},
                       Mrc{"mrc_int8", 0, {1, 2, 3}, {0, 0, 0}, 4, false, 3}}) {
    const int n[3] = {3, 4, 5};
    std::string h(1024 + m.nsymbt, '\0');
    const auto put = [&](std::size_t at, auto v) {
      char b[sizeof(v)];
      std::memcpy(b, &v, sizeof(v));
      if (m.big == (std::endian::native == std::endian::little)) std::reverse(b, b + sizeof(v));
      std::memcpy(h.data() + at, b, sizeof(v));
    };
    for (int c = 0; c < 3; ++c) {
      put(4 * c, std::int32_t{n[c]});
      put(16 + 4 * c, std::int32_t{m.start[c]});
      put(28 + 4 * c, std::int32_t{n[m.map[c] - 1]});
      put(40 + 4 * c, 1.5f * static_cast<float>(n[c]));
      put(52 + 4 * c, 90.0f);
      put(64 + 4 * c, std::int32_t{m.map[c]});
      put(196 + 4 * c, 2.5f * static_cast<float>(c));
    }
    put(12, std::int32_t{m.mode});
    put(92, std::int32_t{m.nsymbt});
    std::memcpy(h.data() + 208, "MAP ", 4);
    h[212] = m.big ? 0x11 : 0x44;
    h[213] = m.big ? 0x11 : 0x41;
    const std::size_t size = m.mode == 0 ? 1 : m.mode == 2 ? 4 : 2;
    for (int i = 0; i < n[0] * n[1] * n[2]; ++i) {
      const int v = (i * 37) % 101 - 50;
      std::string b(size, '\0');
      if (m.mode == 0) b[0] = static_cast<char>(v);
      if (m.mode == 1) {
        const auto x = static_cast<std::int16_t>(v);
        std::memcpy(b.data(), &x, 2);
      }
      if (m.mode == 6) {
        const auto x = static_cast<std::uint16_t>(v + 50);
        std::memcpy(b.data(), &x, 2);
      }
      if (m.mode == 2) {
        const auto x = static_cast<float>(v);
        std::memcpy(b.data(), &x, 4);
      }
      if (m.mode == 12) {
        const std::uint16_t x = 0x3c00;  // 1.0
        std::memcpy(b.data(), &x, 2);
      }
      if (m.big == (std::endian::native == std::endian::little)) std::reverse(b.begin(), b.end());
      h += b;
    }
    seeds.push_back({m.name, with_selector(m.selector, h)});
  }
  // NIfTI and MetaImage as ITK writes them.
  if (itk_available()) {
    ScratchDir dir;
    std::vector<float> f(4 * 3 * 5);
    std::vector<std::int16_t> i16(f.size());
    for (std::size_t i = 0; i < f.size(); ++i) {
      f[i] = static_cast<float>((i * 37) % 101) - 50;
      i16[i] = static_cast<std::int16_t>(f[i]);
    }
    const Mat3 d{0, -1, 0, 1, 0, 0, 0, 0, 1};
    struct Itk {
      const char* name;
      const char* file;
      std::uint8_t selector;
      bool int16;
    };
    for (const Itk& w :
         {Itk{"nifti_float", "a.nii", 1, false}, Itk{"nifti_int16", "b.nii", 1, true},
          Itk{"mha_float", "c.mha", 2, false}, Itk{"mha_int16", "d.mha", 2, true}}) {
      const fs::path p = dir / w.file;
      if (w.int16)
        write_itk(p.string(), i16.data(), ScalarType::Int16, {4, 3, 5}, {1, 2, 3}, {5, 6, 7}, d);
      else
        write_itk(p.string(), f.data(), ScalarType::Float32, {4, 3, 5}, {1, 2, 3}, {5, 6, 7}, d);
      seeds.push_back({w.name, with_selector(w.selector, read_text(p))});
    }
  }
  // A gzip'd MRC map, as EMDB distributes them.
  seeds.push_back({"mrc_float_xyz_gz", with_selector(7, gzip(std::string(seeds[0].bytes.begin() + 1,
                                                                         seeds[0].bytes.end())))});
  if (itk_available()) {
    ScratchDir dir;
    std::vector<std::uint8_t> u8(4 * 3 * 5);
    for (std::size_t i = 0; i < u8.size(); ++i) u8[i] = static_cast<std::uint8_t>((i * 37) % 101);
    write_itk((dir / "e.tif").string(), u8.data(), ScalarType::UInt8, {4, 3, 5}, {1, 1, 1},
              {0, 0, 0}, kIdentity3);
    seeds.push_back({"tiff_multipage", with_selector(5, read_text(dir / "e.tif"))});
    write_itk((dir / "f.nii.gz").string(), u8.data(), ScalarType::UInt8, {4, 3, 5}, {1, 2, 3},
              {5, 6, 7}, kIdentity3);
    seeds.push_back({"nifti_gz", with_selector(6, read_text(dir / "f.nii.gz"))});
    seeds.push_back({"dicom_multiframe", with_selector(4, dicom_multiframe(u8, 4, 3, 5))});
  }
  seeds.push_back({"mrc_truncated", with_selector(0, std::string(100, '\0')), false});
  return seeds;
}

}  // namespace isotile::fuzz
