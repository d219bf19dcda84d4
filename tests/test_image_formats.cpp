// The formats users have (NIfTI, MetaImage, TIFF, DICOM through ITK; MRC/CCP4 by the project's
// own reader): volumes written from the procedural fields must give the raw volume's triangles,
// with positions mapped through the header's transform; real files from ../shared/data; corrupt
// and truncated headers give one clear error line.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "cli_support.h"
#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_io.h"
#include "core/volume/itk_reader.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"
#include "tests/dicom_bytes.h"
#include "tiler/volume_source.h"

// ITK 5.2's NIfTI writer (write_itk, which writes the test volumes) leaks the two file names
// niftiio makes; reading leaks nothing.
extern "C" __attribute__((used)) const char* __lsan_default_suppressions() {
  return "leak:nifti_makeimgname\nleak:nifti_makehdrname\n";
}

namespace isotile {
namespace {

namespace fs = std::filesystem;
using testing::CliResult;
using testing::CliTest;

#define REQUIRE_ITK()                                             \
  do {                                                            \
    if (!itk_available()) ISOTILE_SKIP(Itk, "built without ITK"); \
  } while (0)

// Expects both read_volume and read_volume_header to refuse `path` with an InputError that
// says `what`.
void expect_both_refuse(const fs::path& path, const std::string& what) {
  for (const bool header : {false, true}) {
    try {
      if (header)
        read_volume_header(path.string());
      else
        read_volume(path.string());
      ADD_FAILURE() << path << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  }
}

// A rotation about (1, 2, 3) by 0.4 rad, optionally mirrored in x (determinant -1).
Mat3 test_direction(bool mirror) {
  Vec3d k{1, 2, 3};
  const double len = std::sqrt(14.0);
  for (double& c : k) c /= len;
  const double c = std::cos(0.4), s = std::sin(0.4), t = 1 - c;
  Mat3 r{t * k[0] * k[0] + c,        t * k[0] * k[1] - s * k[2], t * k[0] * k[2] + s * k[1],
         t * k[0] * k[1] + s * k[2], t * k[1] * k[1] + c,        t * k[1] * k[2] - s * k[0],
         t * k[0] * k[2] - s * k[1], t * k[1] * k[2] + s * k[0], t * k[2] * k[2] + c};
  if (mirror)
    for (int row = 0; row < 3; ++row) r[3 * row] = -r[3 * row];
  return r;
}

// The field sampled as the given type: floats as they are, integers as round(1000 v) + 20000.
Volume field_as(const char* spec, ScalarType type) {
  Volume f = make_field_volume(*parse_field_spec(spec));
  if (type == ScalarType::Float32) return f;
  Volume out(type, f.dims());
  const float* src = f.data<float>();
  for (std::int64_t i = 0; i < f.sample_count(); ++i) {
    const double v = std::round(1000.0 * src[i]) + 20000;
    if (type == ScalarType::UInt16)
      out.data<std::uint16_t>()[i] = static_cast<std::uint16_t>(v);
    else
      out.data<std::int16_t>()[i] = static_cast<std::int16_t>(v - 20000);
  }
  return out;
}

double iso_for(ScalarType type) {
  return type == ScalarType::Float32 ? 0.0 : type == ScalarType::UInt16 ? 20000.5 : 0.5;
}

Mesh mc(const VolumeView& v, double iso) {
  ExtractOptions o;
  o.iso = iso;
  o.backend = Backend::Cpu;
  o.normals = true;
  return extract(v, o);
}

// Twice the signed volume enclosed (x6): positive when the faces face outwards.
double signed_volume(const Mesh& m) {
  double s = 0;
  for (const Tri& t : m.triangles) {
    const Vec3f &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    s += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
         a[2] * (b[0] * c[1] - b[1] * c[0]);
  }
  return s;
}

// The raw mesh's vertices (index units: spacing 1, origin 0) through the header's transform
// must be the file's mesh's vertices, its triangles the same (reversed where it mirrors).
void expect_mapped(const Mesh& raw, const Mesh& file, const Vec3d& spacing,
                   const WorldFrame& world) {
  ASSERT_EQ(raw.positions.size(), file.positions.size());
  ASSERT_EQ(raw.triangles.size(), file.triangles.size());
  ASSERT_GT(raw.triangles.size(), 100u);
  const Mat3& d = world.direction;
  const double det = d[0] * (d[4] * d[8] - d[5] * d[7]) - d[1] * (d[3] * d[8] - d[5] * d[6]) +
                     d[2] * (d[3] * d[7] - d[4] * d[6]);
  double worst = 0;
  for (std::size_t i = 0; i < raw.positions.size(); ++i)
    for (int r = 0; r < 3; ++r) {
      double w = world.origin[r];
      for (int c = 0; c < 3; ++c) w += d[3 * r + c] * spacing[c] * raw.positions[i][c];
      worst = std::max(worst, std::abs(w - file.positions[i][r]));
    }
  EXPECT_LT(worst, 1e-4);
  for (std::size_t t = 0; t < raw.triangles.size(); ++t) {
    Tri expect = raw.triangles[t];
    if (det < 0) std::swap(expect[1], expect[2]);
    ASSERT_EQ(expect, file.triangles[t]) << "triangle " << t;
  }
  // Faces still face out of the inside (the sphere's inside is where the field is high).
  EXPECT_GT(signed_volume(file) * (signed_volume(raw) > 0 ? 1 : -1), 0);
}

struct FormatCase {
  const char* name;  // file name
  ScalarType type;
  bool mirror;
  bool oriented;  // whether the format stores origin and direction
};

class ItkFormats : public ::testing::TestWithParam<FormatCase> {};

TEST_P(ItkFormats, FieldGivesTheRawTrianglesInTheHeadersFrame) {
  REQUIRE_ITK();
  const FormatCase c = GetParam();
  const fs::path dir =
      fs::temp_directory_path() / ("isotile-formats-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path path = dir / c.name;
  const Volume raw = field_as("field:torus:28", c.type);
  const Vec3d spacing{0.7, 1.1, 1.3}, origin{10.5, -20.25, 5};
  const Mat3 dir3 = test_direction(c.mirror);
  write_itk(path.string(), raw.bytes(), c.type, raw.dims(), spacing, origin, dir3);

  const Volume v = read_volume(path.string());
  ASSERT_EQ(v.dims(), raw.dims());
  ASSERT_EQ(v.type(), c.type);
  ASSERT_EQ(std::memcmp(v.bytes(), raw.bytes(), raw.byte_size()), 0);
  ASSERT_TRUE(v.world());
  // TIFF keeps x and y resolution only.
  for (int a = 0; a < (c.oriented ? 3 : 2); ++a) EXPECT_NEAR(v.spacing()[a], spacing[a], 1e-6);
  if (c.oriented) {
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(v.world()->origin[a], origin[a], 1e-5);
    for (int i = 0; i < 9; ++i) EXPECT_NEAR(v.world()->direction[i], dir3[i], 1e-5) << i;
  }
  Mesh m = mc(v.view(), iso_for(c.type));
  apply_frame(mesh_frame(v.view()), m);
  expect_mapped(mc(raw.view(), iso_for(c.type)), m, v.spacing(), *v.world());

  // The header alone says the same; the tiler reads the same samples.
  const VolumeHeader h = read_volume_header(path.string());
  EXPECT_EQ(h.dims, raw.dims());
  auto source = open_volume_source(path.string(), {});
  std::vector<std::byte> box(raw.byte_size());
  source->read({{0, 0, 0}, raw.dims()}, box.data());
  EXPECT_EQ(std::memcmp(box.data(), raw.bytes(), raw.byte_size()), 0);
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Formats, ItkFormats,
                         ::testing::Values(FormatCase{"f.nii", ScalarType::Float32, false, true},
                                           FormatCase{"f.nii.gz", ScalarType::Int16, true, true},
                                           FormatCase{"f.mha", ScalarType::Float32, true, true},
                                           FormatCase{"f.mhd", ScalarType::UInt16, false, true},
                                           FormatCase{"f.tif", ScalarType::UInt16, false, false}),
                         [](const auto& info) {
                           std::string n = info.param.name;
                           for (char& ch : n)
                             if (ch == '.') ch = '_';
                           return n;
                         });

// Single-page TIFFs stacked from a directory (name order, numbers as numbers) or a numbered
// pattern.
TEST(ItkRegions, TiffSlicesFromADirectoryOrAPattern) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-tiffs-" + std::to_string(::getpid()));
  fs::create_directories(dir / "slices");
  const Volume raw = field_as("field:sphere:16", ScalarType::UInt16);
  const std::size_t plane = static_cast<std::size_t>(16 * 16);
  fs::create_directories(dir / "unpadded");
  for (int k = 0; k < 16; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "s_%03d.tif", k + 1);
    write_itk((dir / "slices" / name).string(), raw.data<std::uint16_t>() + k * plane,
              ScalarType::UInt16, {16, 16, 1}, {1, 1, 1}, {0, 0, 0}, kIdentity3);
    // Numbers as many programs write them, not padded: img_2 comes before img_10 (in text
    // order it came after img_19, scrambling the planes).
    std::snprintf(name, sizeof name, "img_%d_x%d.tif", k, 16 - k);
    write_itk((dir / "unpadded" / name).string(), raw.data<std::uint16_t>() + k * plane,
              ScalarType::UInt16, {16, 16, 1}, {1, 1, 1}, {0, 0, 0}, kIdentity3);
  }
  for (const fs::path& input : {dir / "slices", dir / "slices" / "s_%03d.tif", dir / "unpadded"}) {
    SCOPED_TRACE(input.string());
    const Volume v = read_volume(input.string());
    ASSERT_EQ(v.dims(), raw.dims());
    ASSERT_EQ(v.type(), ScalarType::UInt16);
    EXPECT_EQ(std::memcmp(v.bytes(), raw.bytes(), raw.byte_size()), 0);
    // Uncompressed slices are read plane by plane out of core, in the stack's order.
    auto source = open_volume_source(input.string(), {});
    EXPECT_FALSE(source->in_memory());
    const Box3 box{{2, 3, 4}, {13, 9, 15}};
    std::vector<std::uint16_t> got(11 * 6 * 11);
    source->read(box, got.data());
    for (std::int64_t k = 0; k < 11; ++k)
      for (std::int64_t j = 0; j < 6; ++j)
        for (std::int64_t i = 0; i < 11; ++i)
          ASSERT_EQ(got[(k * 6 + j) * 11 + i],
                    raw.data<std::uint16_t>()[((4 + k) * 16 + 3 + j) * 16 + 2 + i]);
  }
  // A directory of numbered slices with one missing, or with a file outside their numbering, is
  // refused as the pattern's stack is (every slice above the gap moved down a spacing, and a
  // stray notes.tif became a slice, exit 0).
  fs::create_directories(dir / "gap");
  for (int k : {1, 2, 3, 4, 6, 7})
    fs::copy_file(dir / "slices" / ("s_00" + std::to_string(k) + ".tif"),
                  dir / "gap" / ("s_00" + std::to_string(k) + ".tif"));
  expect_both_refuse(dir / "gap", "slice number 5 is missing, between s_004.tif and s_006.tif");
  fs::copy_file(dir / "slices" / "s_005.tif", dir / "gap" / "s_005.tif");
  EXPECT_EQ(read_volume((dir / "gap").string()).dims()[2], 7);
  fs::copy_file(dir / "slices" / "s_005.tif", dir / "gap" / "notes.tif");
  expect_both_refuse(dir / "gap", "notes.tif is not numbered as its other 7 slices are (s_N.tif)");
  // A slice of another size is an error naming it.
  write_itk((dir / "slices" / "s_017.tif").string(), raw.bytes(), ScalarType::UInt16, {8, 8, 1},
            {1, 1, 1}, {0, 0, 0}, kIdentity3);
  EXPECT_THROW(read_volume((dir / "slices").string()), InputError);
  fs::remove_all(dir);
}

// A numbered pattern is expanded by isotile, never given to printf (a %s or %n would read or
// write through a stray pointer), and a stack with a slice missing is refused, not cut short.
TEST(ItkRegions, ASlicePatternIsANumberAndEverySliceIsThere) {
  REQUIRE_ITK();
  const fs::path dir =
      fs::temp_directory_path() / ("isotile-pattern-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Volume raw = field_as("field:sphere:16", ScalarType::UInt16);
  const std::size_t plane = static_cast<std::size_t>(16 * 16);
  auto write_slice = [&](int k, const char* format) {
    char name[32];
    std::snprintf(name, sizeof name, format, k);
    write_itk((dir / name).string(), raw.data<std::uint16_t>() + (k % 16) * plane,
              ScalarType::UInt16, {16, 16, 1}, {1, 1, 1}, {0, 0, 0}, kIdentity3);
  };
  for (int k = 1; k <= 16; ++k) write_slice(k, "p_%d.tif");
  EXPECT_EQ(read_volume_header((dir / "p_%d.tif").string()).dims, (Index3{16, 16, 16}));
  for (const char* bad : {"p_%s.tif", "p_%n.tif", "p_%d_%d.tif", "p_%x.tif", "p_%.tif"}) {
    SCOPED_TRACE(bad);
    try {
      read_volume_header((dir / bad).string());
      ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("not a slice pattern"), std::string::npos) << e.what();
    }
  }
  // Slices 0 to 9 and 11 to 14 of a zero-padded stack: refused, naming the missing slice.
  for (int k = 0; k < 15; ++k)
    if (k != 10) write_slice(k, "z_%03d.tif");
  expect_both_refuse(dir / "z_%03d.tif", "z_010.tif is missing");
  write_slice(10, "z_%03d.tif");
  EXPECT_EQ(read_volume((dir / "z_%03d.tif").string()).dims(), (Index3{16, 16, 15}));
  fs::remove_all(dir);
}

// Plainly stored NIfTI and MetaImage are read box by box; gzip'd NIfTI is read whole.
TEST(ItkRegions, PlainFilesAreReadByRegion) {
  REQUIRE_ITK();
  const fs::path dir =
      fs::temp_directory_path() / ("isotile-regions-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Volume raw = field_as("field:sphere:20", ScalarType::Float32);
  for (const char* name : {"r.nii", "r.mha", "r.nii.gz"}) {
    const fs::path p = dir / name;
    write_itk(p.string(), raw.bytes(), raw.type(), raw.dims(), {1, 1, 1}, {0, 0, 0}, kIdentity3);
    auto source = open_volume_source(p.string(), {});
    const bool gz = std::string(name).ends_with(".gz");
    EXPECT_EQ(source->in_memory(), gz) << name;
    const Box3 box{{3, 4, 5}, {11, 9, 17}};
    std::vector<float> got(8 * 5 * 12);
    source->read(box, got.data());
    for (std::int64_t k = 0; k < 12; ++k)
      for (std::int64_t j = 0; j < 5; ++j)
        for (std::int64_t i = 0; i < 8; ++i)
          ASSERT_EQ(got[(k * 5 + j) * 8 + i], raw.view().value(3 + i, 4 + j, 5 + k)) << name;
    if (gz) {
      // Read whole: refused when the volume does not fit the budget.
      EXPECT_THROW(open_volume_source(p.string(), {}, 1000), InputError);
    }
  }
  fs::remove_all(dir);
}

// A multi-page classic TIFF of one strip per page, written by hand so that its layout is known:
// `order` 'I' or 'M' (the samples in that byte order too), `gap` bytes between pages' samples,
// `compression` as tag 259 says (the samples are stored plainly whatever it says: only the
// check reads them), `orientation` 0 for no tag 274.
// `tags` replace or add short, long or rational values (tag, type 3, 4 or 5, value, and a
// rational's denominator) on every page, and `description` is page 1's ImageDescription where not
// empty (every page's with `on_every_page`).
struct TiffTag {
  std::uint16_t tag, type;
  std::uint32_t value, denominator = 1;
};
void write_tiff_pages(const fs::path& path, const Volume& v, char order, std::uint32_t gap = 0,
                      std::uint16_t compression = 1, std::uint16_t orientation = 0,
                      const std::vector<TiffTag>& tags = {}, const std::string& description = "",
                      bool on_every_page = false) {
  const bool big = order == 'M';
  std::string out;
  auto put = [&](std::uint64_t x, int bytes) {
    for (int i = 0; i < bytes; ++i)
      out.push_back(static_cast<char>((x >> (8 * (big ? bytes - 1 - i : i))) & 0xff));
  };
  const std::size_t size = scalar_size(v.type());
  const std::uint32_t plane = static_cast<std::uint32_t>(v.dims()[0] * v.dims()[1] * size);
  const auto pages = static_cast<std::uint32_t>(v.dims()[2]);
  out.append(2, order);
  put(42, 2);
  // The first directory, after the samples, the description and the rationals' values.
  const std::uint32_t text_at = 8 + pages * (plane + gap);
  const auto text_size = static_cast<std::uint32_t>(description.size() + 1);
  const std::uint32_t rationals_at = text_at + (description.empty() ? 0 : text_size);
  std::vector<std::uint32_t> rationals;  // numerator, denominator, ...
  for (const TiffTag& t : tags)
    if (t.type == 5) rationals.insert(rationals.end(), {t.value, t.denominator});
  put(rationals_at + 4 * static_cast<std::uint32_t>(rationals.size()), 4);
  const auto* bytes = reinterpret_cast<const unsigned char*>(v.bytes());
  for (std::uint32_t k = 0; k < pages; ++k) {
    for (std::uint32_t i = 0; i < plane; i += static_cast<std::uint32_t>(size))
      for (std::size_t b = 0; b < size; ++b)  // the sample's bytes in the file's order
        out.push_back(static_cast<char>(bytes[k * plane + i + (big ? size - 1 - b : b)]));
    out.append(gap, '\0');
  }
  if (!description.empty()) out.append(description.c_str(), text_size);
  for (const std::uint32_t r : rationals) put(r, 4);
  const ScalarType t = v.type();
  const std::uint16_t format =
      is_floating(t)                                                              ? 3
      : t == ScalarType::Int8 || t == ScalarType::Int16 || t == ScalarType::Int32 ? 2
                                                                                  : 1;
  for (std::uint32_t k = 0; k < pages; ++k) {
    struct Entry {
      std::uint16_t tag, type;
      std::uint32_t value, count = 1;
    };
    std::vector<Entry> e = {{256, 4, static_cast<std::uint32_t>(v.dims()[0])},
                            {257, 4, static_cast<std::uint32_t>(v.dims()[1])},
                            {258, 3, static_cast<std::uint32_t>(8 * size)},
                            {259, 3, compression},
                            {262, 3, 1},
                            {273, 4, 8 + k * (plane + gap)},
                            {274, 3, orientation},
                            {277, 3, 1},
                            {278, 4, static_cast<std::uint32_t>(v.dims()[1])},
                            {279, 4, plane},
                            {339, 3, format}};
    if (orientation == 0) e.erase(e.begin() + 6);
    std::uint32_t rational = 0;
    for (const TiffTag& t : tags) {
      const Entry entry{t.tag, t.type, t.type == 5 ? rationals_at + 8 * rational++ : t.value};
      const auto at =
          std::find_if(e.begin(), e.end(), [&](const Entry& x) { return x.tag == t.tag; });
      if (at != e.end())
        *at = entry;
      else
        e.push_back(entry);
    }
    if (!description.empty() && (k == 0 || on_every_page))
      e.push_back({270, 2, text_at, text_size});
    std::sort(e.begin(), e.end(), [](const Entry& a, const Entry& b) { return a.tag < b.tag; });
    put(e.size(), 2);
    for (const Entry& x : e) {
      put(x.tag, 2);
      put(x.type, 2);
      put(x.count, 4);
      put(x.value, x.type == 3 ? 2 : 4);
      if (x.type == 3) put(0, 2);
    }
    const std::size_t next = out.size() + 4;
    put(k + 1 < pages ? next : 0, 4);
  }
  std::ofstream(path, std::ios::binary) << out;
}

// A TIFF whose pages' samples follow each other uncompressed (as ImageJ writes stacks) is read
// box by box out of core, in either byte order, with the samples ITK reads; other layouts are
// read whole.
TEST(ItkRegions, TiffPagesStoredInARowAreReadByRegion) {
  REQUIRE_ITK();
  const fs::path dir =
      fs::temp_directory_path() / ("isotile-tiff-pages-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  struct Case {
    const char* name;
    ScalarType type;
    char order;
    std::uint32_t gap;
    std::uint16_t orientation;
    bool by_region;
  };
  for (const Case& c : {Case{"u16_le", ScalarType::UInt16, 'I', 0, 0, true},
                        Case{"u16_be", ScalarType::UInt16, 'M', 0, 1, true},
                        Case{"i16_be", ScalarType::Int16, 'M', 0, 0, true},
                        Case{"f32_be", ScalarType::Float32, 'M', 0, 0, true},
                        // ITK's reader reads none of these samples; isotile reads them itself.
                        Case{"i32_le", ScalarType::Int32, 'I', 0, 0, true},
                        Case{"u32_be", ScalarType::UInt32, 'M', 0, 0, true},
                        Case{"gap", ScalarType::UInt16, 'I', 2, 0, false},
                        Case{"bottom_up", ScalarType::UInt16, 'I', 0, 4, false}}) {
    SCOPED_TRACE(c.name);
    const Volume raw = field_as("field:torus:20", c.type);
    const fs::path p = dir / (std::string(c.name) + ".tif");
    write_tiff_pages(p, raw, c.order, c.gap, 1, c.orientation);
    const Volume whole = read_volume(p.string());
    ASSERT_EQ(whole.dims(), raw.dims());
    ASSERT_EQ(whole.type(), c.type);
    if (c.orientation != 4) {  // (ITK applies no orientation: the rows as stored either way)
      ASSERT_EQ(std::memcmp(whole.bytes(), raw.bytes(), raw.byte_size()), 0);
    }
    auto source = open_volume_source(p.string(), {});
    EXPECT_EQ(source->in_memory(), !c.by_region);
    const Box3 box{{3, 4, 5}, {11, 9, 17}};
    const std::size_t size = scalar_size(c.type);
    std::vector<std::byte> got(8 * 5 * 12 * size);
    source->read(box, got.data());
    for (std::int64_t k = 0; k < 12; ++k)
      for (std::int64_t j = 0; j < 5; ++j)
        ASSERT_EQ(std::memcmp(got.data() + ((k * 5 + j) * 8) * size,
                              static_cast<const std::byte*>(whole.bytes()) +
                                  (((5 + k) * 20 + 4 + j) * 20 + 3) * size,
                              8 * size),
                  0)
            << "row " << j << " plane " << k;
    if (!c.by_region) {
      EXPECT_THROW(open_volume_source(p.string(), {}, 1000), InputError);
    }
  }
  // Other orientations take ITK's reader down libtiff's colour path: refused naming the tag (it
  // said "4 components per sample (e.g. colour)" of gray pages).
  for (const std::uint16_t orientation : {2, 3, 5, 8}) {
    write_tiff_pages(dir / "turned.tif", field_as("field:torus:20", ScalarType::UInt16), 'I', 0, 1,
                     orientation);
    try {
      read_volume((dir / "turned.tif").string());
      ADD_FAILURE() << orientation;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("TIFF page 1 has Orientation " +
                                           std::to_string(orientation) + " ("),
                std::string::npos)
          << e.what();
    }
  }
  // Compressed pages are ITK's to decode (here PackBits' tag over plain bytes; the header alone
  // is read, not the samples).
  write_tiff_pages(dir / "packbits.tif", field_as("field:torus:20", ScalarType::UInt16), 'I', 0,
                   32773);
  EXPECT_FALSE(read_volume_header((dir / "packbits.tif").string()).plain);
  // Pages ITK's reader would read wrong are refused, naming what they hold: two samples per
  // pixel (it read half of each row, the two interleaved), tiles (read as colour), samples of
  // other sizes, and ImageJ hyperstacks of several channels or time points (stacked along z).
  const Volume u16 = field_as("field:torus:20", ScalarType::UInt16);
  struct Refused {
    const char* name;
    std::vector<TiffTag> tags;
    std::string description, says;
    bool every_page = false;
  };
  for (const Refused& r :
       {Refused{"two_samples", {{277, 3, 2}, {258, 3, 8}}, "", "2 samples per pixel"},
        Refused{"tiles", {{322, 4, 20}, {323, 4, 20}}, "", "stored in tiles of 20x20"},
        Refused{"bits12", {{258, 3, 12}}, "", "12-bit TIFF samples cannot be read"},
        Refused{"channels",
                {},
                "ImageJ=1.54f\nimages=20\nchannels=2\nslices=10\nhyperstack=true\n",
                "an ImageJ hyperstack of 2 channels, not one volume"},
        Refused{"frames",
                {},
                "ImageJ=1.54f\nimages=20\nslices=10\nframes=2\n",
                "an ImageJ hyperstack of 2 time points, not one volume"},
        // tifffile's description of an array of z and channels, and of two series in one file.
        Refused{"zcyx",
                {},
                "{\"shape\": [10, 2, 20, 20]}",
                "tifffile wrote an array of shape [10, 2, 20, 20] here"},
        Refused{"series",
                {},
                "{\"shape\": [1, 20, 20]}",
                "TIFF page 2 begins a second series",
                true}}) {
    const fs::path p = dir / (std::string(r.name) + ".tif");
    write_tiff_pages(p, u16, 'I', 0, 1, 0, r.tags, r.description, r.every_page);
    try {
      read_volume_header(p.string());
      ADD_FAILURE() << r.name << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(r.says), std::string::npos) << e.what();
    }
  }
  // ImageJ's description of a plain stack is no hyperstack, nor tifffile's of one 3-D array.
  write_tiff_pages(dir / "imagej.tif", u16, 'I', 0, 1, 0, {},
                   "ImageJ=1.54f\nimages=20\nslices=20\nchannels=1\nunit=micron\n");
  EXPECT_EQ(read_volume((dir / "imagej.tif").string()).dims(), u16.dims());
  write_tiff_pages(dir / "tifffile.tif", u16, 'I', 0, 1, 0, {},
                   "{\"axes\": \"ZYX\", \"shape\": [20, 20, 20]}");
  EXPECT_EQ(read_volume((dir / "tifffile.tif").string()).dims(), u16.dims());
  // A plain stack whatever its one axis is called (tifffile's imagej=True calls z channels), and
  // tifffile's slices written one by one (a series of one plane each, alike): stacks of planes.
  for (const char* axis : {"channels", "frames"}) {
    write_tiff_pages(dir / "one_axis.tif", u16, 'I', 0, 1, 0, {},
                     "ImageJ=1.11a\nimages=20\n" + std::string(axis) + "=20\nhyperstack=true\n");
    EXPECT_EQ(read_volume((dir / "one_axis.tif").string()).dims(), u16.dims()) << axis;
  }
  write_tiff_pages(dir / "planes.tif", u16, 'I', 0, 1, 0, {}, "{\"shape\": [20, 20]}", true);
  EXPECT_EQ(read_volume((dir / "planes.tif").string()).dims(), u16.dims());
  // 32-bit integers stored otherwise: refused (ITK would leave the volume unwritten).
  for (const std::uint32_t gap : {0u, 2u}) {
    const fs::path p = dir / ("i32_" + std::to_string(gap) + ".tif");
    write_tiff_pages(p, field_as("field:torus:20", ScalarType::Int32), 'I', gap, gap ? 1 : 32773);
    expect_both_refuse(p, "32-bit integer TIFF samples are read only when");
  }
  fs::remove_all(dir);
}

// ImageJ's calibration (the pixel size as 1 / XResolution and 1 / YResolution, in the unit its
// description names, the voxel depth as `spacing=`) is the volume's spacing, in that unit (mm
// for the centimetre and the inch, as ITK gives those), as ImageJ reads it. ITK reads resolution
// tags of no unit as a spacing of 1: such a stack of 0.5 um pixels 2.5 um apart was read as 1, 1,
// 1, its mesh squashed five times along z against x.
TEST(ItkRegions, ImageJCalibrationIsTheSpacing) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-ij-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Volume u16 = field_as("field:torus:20", ScalarType::UInt16);
  struct Case {
    const char* name;
    std::uint32_t x_per_unit, y_per_unit;
    std::uint16_t unit_tag;
    const char* description;
    Vec3d spacing;
    const char* unit;
  };
  for (const Case& c :
       {Case{"micron", 2, 4, 1, "unit=micron\nspacing=2.5\n", {0.5, 0.25, 2.5}, "micron"},
        // Centimetre tags (ITK's mm) and a depth in cm: mm throughout.
        Case{"cm", 20, 20, 3, "unit=cm\nspacing=0.25\n", {0.5, 0.5, 2.5}, "mm"},
        // Centimetre tags with "um" named: micrometres, as ImageJ reads them (x and y came out
        // 10^4 too small beside z).
        Case{"cm_um", 20000, 20000, 3, "unit=um\nspacing=2.5\n", {0.5, 0.5, 2.5}, "um"},
        // ImageJ's escape for a unit outside ASCII, and a negative depth (ImageJ takes its
        // size).
        Case{"mu", 2, 2, 1, "unit=\\u00B5m\nspacing=-2.5\n", {0.5, 0.5, 2.5}, "\u00b5m"},
        Case{"no_depth", 10, 10, 1, "unit=nm\n", {0.1, 0.1, 1}, "nm"},
        Case{"pixel", 1, 1, 1, "unit=pixel\n", {1, 1, 1}, ""}}) {
    const fs::path p = dir / (std::string(c.name) + ".tif");
    write_tiff_pages(p, u16, 'I', 0, 1, 0,
                     {{282, 5, c.x_per_unit}, {283, 5, c.y_per_unit}, {296, 3, c.unit_tag}},
                     std::string("ImageJ=1.54f\nimages=20\nslices=20\n") + c.description);
    const VolumeHeader h = read_volume_header(p.string());
    const Volume v = read_volume(p.string());
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(h.spacing[a], c.spacing[a], 1e-12) << c.name << " axis " << a;
      EXPECT_EQ(v.spacing()[a], h.spacing[a]) << c.name << " axis " << a;
    }
    EXPECT_EQ(h.spacing_unit, c.unit) << c.name;
    // Given, --spacing replaces the calibration and its unit.
    RawOptions given;
    given.spacing = Vec3d{1, 2, 3};
    const VolumeHeader replaced = read_volume_header(p.string(), given);
    EXPECT_EQ(replaced.spacing, (Vec3d{1, 2, 3})) << c.name;
    EXPECT_EQ(replaced.spacing_unit, "") << c.name;
  }
  // Axes in different units, and a depth that is no number: refused.
  for (const auto& [description, says] :
       {std::pair{"unit=micron\nzunit=nm\n", "axes in different units (micron, nm)"},
        std::pair{"unit=micron\nspacing=abc\n", "voxel depth 'spacing=abc' is not a number"}}) {
    const fs::path p = dir / "refused.tif";
    write_tiff_pages(p, u16, 'I', 0, 1, 0, {{282, 5, 2}, {283, 5, 2}, {296, 3, 1}},
                     std::string("ImageJ=1.54f\nimages=20\nslices=20\n") + description);
    expect_both_refuse(p, says);
  }
  fs::remove_all(dir);
}

// ImageJ's layout for stacks past 4 GiB (and tifffile's imagej=True, truncate=True): one page
// directory, `images=N` in its description, the planes one after another. Read as ImageJ reads
// it, in core and by region, with its calibration (it was refused as "one TIFF page").
TEST(ItkRegions, ImageJStacksInOnePageDirectory) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-ij1-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Volume u16 = field_as("field:torus:20", ScalarType::UInt16);
  // Every page's directory written, then the chain cut after the first.
  const auto one_directory = [&](const fs::path& p, std::uint16_t compression, int images) {
    const std::string n = std::to_string(images);
    write_tiff_pages(
        p, u16, 'I', 0, compression, 0, {{282, 5, 2}, {283, 5, 2}, {296, 3, 1}},
        "ImageJ=1.54f\nimages=" + n + "\nslices=" + n + "\nunit=micron\nspacing=2.5\n");
    std::string bytes = testing::slurp(p);
    std::uint32_t ifd = 0;
    std::uint16_t entries = 0;
    std::memcpy(&ifd, bytes.data() + 4, 4);
    std::memcpy(&entries, bytes.data() + ifd, 2);
    std::memset(bytes.data() + ifd + 2 + 12 * entries, 0, 4);
    std::ofstream(p, std::ios::binary) << bytes;
  };
  const fs::path p = dir / "one.tif";
  one_directory(p, 1, 20);
  const VolumeHeader h = read_volume_header(p.string());
  EXPECT_EQ(h.dims, u16.dims());
  EXPECT_EQ(h.spacing, (Vec3d{0.5, 0.5, 2.5}));
  EXPECT_EQ(h.spacing_unit, "micron");
  const Volume v = read_volume(p.string());
  ASSERT_EQ(v.dims(), u16.dims());
  EXPECT_EQ(std::memcmp(v.bytes(), u16.bytes(), u16.byte_size()), 0);
  auto source = open_volume_source(p.string(), {});
  EXPECT_FALSE(source->in_memory());
  std::vector<std::uint16_t> got(4 * 5 * 6);
  source->read({{3, 4, 12}, {7, 9, 18}}, got.data());
  for (std::int64_t k = 0; k < 6; ++k)
    for (std::int64_t j = 0; j < 5; ++j)
      for (std::int64_t i = 0; i < 4; ++i)
        ASSERT_EQ(got[(k * 5 + j) * 4 + i],
                  u16.data<std::uint16_t>()[((12 + k) * 20 + 4 + j) * 20 + 3 + i]);
  // Counting more planes than the file holds: refused, naming the bytes (not a stack cut short).
  one_directory(dir / "short.tif", 1, 40);
  expect_both_refuse(dir / "short.tif", "an ImageJ stack of 40 images in one page directory needs");
  // Compressed, the planes cannot be found.
  one_directory(dir / "packed.tif", 5, 20);
  expect_both_refuse(dir / "packed.tif", "whose samples are not stored plainly");
  fs::remove_all(dir);
}

// A directory or pattern of ImageJ slices, as ImageJ's Save As > Image Sequence writes them:
// their calibration is the stack's, as ImageJ's import reads it (ITK read none of it: 0.5 x
// 0.25 um pixels came out at 1, 1, 1). Slices calibrated differently are refused.
TEST(ItkRegions, ImageJSlicesKeepTheirCalibration) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-ijs-" + std::to_string(::getpid()));
  fs::create_directories(dir / "ij");
  const Volume u16 = field_as("field:torus:20", ScalarType::UInt16);
  const std::size_t plane = 20 * 20 * sizeof(std::uint16_t);
  const auto write_slice = [&](int k, std::uint32_t x_per_unit, const std::string& description) {
    Volume slice(ScalarType::UInt16, {20, 20, 1});
    std::memcpy(slice.bytes(), u16.bytes() + k * plane, plane);
    char name[32];
    std::snprintf(name, sizeof name, "s_%03d.tif", k + 1);
    write_tiff_pages(dir / "ij" / name, slice, 'I', 0, 1, 0,
                     {{282, 5, x_per_unit}, {283, 5, 4}, {296, 3, 1}}, description);
  };
  for (int k = 0; k < 20; ++k) write_slice(k, 2, "ImageJ=1.54f\nunit=micron\n");
  for (const fs::path& input : {dir / "ij", dir / "ij" / "s_%03d.tif"}) {
    SCOPED_TRACE(input.string());
    const VolumeHeader h = read_volume_header(input.string());
    const Volume v = read_volume(input.string());
    EXPECT_EQ(h.spacing, (Vec3d{0.5, 0.25, 1}));
    EXPECT_EQ(h.spacing_unit, "micron");
    EXPECT_EQ(v.spacing(), h.spacing);
    ASSERT_EQ(v.dims(), u16.dims());
    EXPECT_EQ(std::memcmp(v.bytes(), u16.bytes(), u16.byte_size()), 0);
  }
  // One slice of another pixel size, or none: which holds is anyone's guess.
  write_slice(4, 3, "ImageJ=1.54f\nunit=micron\n");
  expect_both_refuse(dir / "ij", "its slices are calibrated differently");
  write_slice(4, 2, "");
  expect_both_refuse(dir / "ij", "uncalibrated");
  // --spacing reads them anyway, as the message says.
  RawOptions given;
  given.spacing = Vec3d{1, 2, 3};
  EXPECT_EQ(read_volume_header((dir / "ij").string(), given).spacing, (Vec3d{1, 2, 3}));
  EXPECT_EQ(read_volume((dir / "ij").string(), given).spacing(), (Vec3d{1, 2, 3}));
  fs::remove_all(dir);
}

// NaN and Inf in a NIfTI file's floating-point samples are refused, as in every other format:
// ITK's nifti library turned them into 0, and the volume was meshed with exit 0 (--memory, which
// reads plain samples itself, refused it).
TEST(ItkRegions, NiftiNanSamplesAreRefused) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-nan-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  for (const ScalarType type : {ScalarType::Float32, ScalarType::Float64}) {
    Volume v(type, {5, 6, 7});
    visit_scalar(type, [&](auto tag) {
      using T = decltype(tag);
      for (std::int64_t i = 0; i < v.sample_count(); ++i) v.data<T>()[i] = static_cast<T>(i % 9);
      v.data<T>()[1 + 5 * (2 + 6 * 3)] = std::numeric_limits<T>::quiet_NaN();
    });
    // Plain, gzip'd, and rescaled (scl_slope 2.5: read through ITK, checked in the file first).
    for (const char* name : {"n.nii", "n.nii.gz", "scaled.nii"}) {
      SCOPED_TRACE(std::string(scalar_name(type)) + " " + name);
      const fs::path p = dir / name;
      write_itk(p.string(), v.bytes(), type, v.dims(), {1, 1, 1}, {0, 0, 0}, kIdentity3);
      if (std::string(name) == "scaled.nii") {
        std::string bytes = testing::slurp(p);
        const float slope = 2.5f;
        std::memcpy(bytes.data() + 112, &slope, 4);
        std::ofstream(p, std::ios::binary) << bytes;
        ASSERT_TRUE(read_volume_header(p.string()).rescaled);
      }
      try {
        read_volume(p.string());
        ADD_FAILURE() << "read";
      } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("1 sample is NaN or Inf (first at x=1, y=2, z=3)"),
                  std::string::npos)
            << e.what();
      }
    }
  }
  fs::remove_all(dir);
}

// MetaImage's text samples (BinaryData = False) are checked against what MetaIO read: it reads a
// double and casts it (300 in a MET_UCHAR file read 44, exit 0). 1e2 is the number it is.
TEST(ItkRegions, MetaImageTextSamplesAreTheirNumbers) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-mtext-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path mha = dir / "t.mha";
  const auto metaimage = [&](const std::string& samples) {
    std::ofstream(mha, std::ios::binary)
        << "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\n"
           "BinaryData = False\nElementDataFile = LOCAL\n"
        << samples << "\n";
  };
  metaimage("1 2 3 4 5 1e2 7 8");
  EXPECT_EQ(read_volume(mha.string()).data<std::uint8_t>()[5], 100);
  for (const auto& [token, says] :
       {std::pair{"300", "is '300', out of the uint8 range (0 to 255)"},
        std::pair{"2.7", "is '2.7', not an integer, as uint8 samples are"}}) {
    metaimage(std::string("1 2 3 4 5 ") + token + " 7 8");
    try {
      read_volume(mha.string());
      ADD_FAILURE() << token << " read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("MetaImage text sample 5 (x=1, y=0, z=1) ") +
                                           says),
                std::string::npos)
          << e.what();
    }
  }
  fs::remove_all(dir);
}

// NIfTI's units (xyzt_units) apply to the whole transform: ITK scales the spacing to
// millimetres, and the origin must follow (a micron file's mesh lay 1000 times too far from 0
// for its size). A pixdim of 0 without an sform is no spacing (ITK read it as 1): refused,
// unless --spacing gives one.
TEST(ItkRegions, NiftiUnitsScaleTheOriginAndPixdimZeroIsRefused) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-units-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  Volume v(ScalarType::UInt8, {5, 6, 7});
  for (std::int64_t i = 0; i < v.sample_count(); ++i) v.data<std::uint8_t>()[i] = i % 7;
  const fs::path p = dir / "u.nii";
  write_itk(p.string(), v.bytes(), v.type(), v.dims(), {0.5, 2, 3}, {10, -20, 30}, kIdentity3);
  const std::string written = testing::slurp(p);
  for (const auto& [units, scale] : {std::pair{1, 1e3}, std::pair{2, 1.0}, std::pair{3, 1e-3}}) {
    SCOPED_TRACE(units);
    std::string bytes = written;
    bytes[123] = static_cast<char>((bytes[123] & ~7) | units);
    std::ofstream(p, std::ios::binary) << bytes;
    const VolumeHeader h = read_volume_header(p.string());
    const Volume r = read_volume(p.string());
    const Vec3d spacing{0.5, 2, 3}, origin{10, -20, 30};
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(h.spacing[a], spacing[a] * scale, 1e-9 * scale);
      EXPECT_NEAR(h.origin[a], origin[a] * scale, 1e-6 * scale);
      EXPECT_NEAR(h.world->origin[a], origin[a] * scale, 1e-6 * scale);
      EXPECT_EQ(r.origin()[a], h.origin[a]);
      EXPECT_EQ(r.world()->origin[a], h.origin[a]);
    }
  }
  std::string bytes = written;
  const float zero = 0;
  std::memcpy(bytes.data() + 84, &zero, 4);  // pixdim[2]
  bytes[254] = bytes[255] = 0;               // no sform
  std::ofstream(p, std::ios::binary) << bytes;
  for (const bool header : {true, false}) {
    try {
      header ? (void)read_volume_header(p.string()) : (void)read_volume(p.string());
      ADD_FAILURE() << "pixdim 0 read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("NIfTI pixdim[2] (the spacing along y) is 0"),
                std::string::npos)
          << e.what();
    }
  }
  RawOptions given;
  given.spacing = Vec3d{0.5, 1.5, 3};
  EXPECT_EQ(read_volume(p.string(), given).spacing(), *given.spacing);
  fs::remove_all(dir);
}

// NIfTI's scl_slope and scl_inter are applied; such a file is read whole out of core.
TEST(ItkRegions, NiftiRescaleIsApplied) {
  REQUIRE_ITK();
  const fs::path dir = fs::temp_directory_path() / ("isotile-scl-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  Volume v(ScalarType::Int16, {5, 4, 3});
  for (std::int64_t i = 0; i < v.sample_count(); ++i)
    v.data<std::int16_t>()[i] = static_cast<std::int16_t>(i - 20);
  const fs::path p = dir / "s.nii";
  write_itk(p.string(), v.bytes(), v.type(), v.dims(), {1, 1, 1}, {0, 0, 0}, kIdentity3);
  std::string bytes = testing::slurp(p);
  const float slope = 2.5f, inter = -5;
  std::memcpy(bytes.data() + 112, &slope, 4);
  std::memcpy(bytes.data() + 116, &inter, 4);
  std::ofstream(p, std::ios::binary) << bytes;
  const VolumeHeader h = read_volume_header(p.string());
  EXPECT_TRUE(h.rescaled);
  EXPECT_EQ(h.rescale_slope, 2.5);
  EXPECT_EQ(h.rescale_intercept, -5);
  const Volume r = read_volume(p.string());
  for (std::int64_t i = 0; i < v.sample_count(); ++i)
    EXPECT_EQ(r.view().value(i % 5, i / 5 % 4, i / 20), 2.5 * (i - 20) - 5) << i;
  EXPECT_TRUE(open_volume_source(p.string(), {})->in_memory());
  // A slope of 0 or NaN means no scaling, intercept included (NIfTI), where ITK adds the
  // intercept: refused, naming both. With an intercept of 0, the samples as stored.
  for (const float zero : {0.0f, std::numeric_limits<float>::quiet_NaN()}) {
    std::memcpy(bytes.data() + 112, &zero, 4);
    std::ofstream(p, std::ios::binary) << bytes;
    try {
      read_volume(p.string());
      ADD_FAILURE() << "an intercept without a slope applied";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("with scl_inter -5: NIfTI reads the samples unscaled"),
                std::string::npos)
          << e.what();
    }
  }
  const float none = 0;
  std::memcpy(bytes.data() + 116, &none, 4);
  std::ofstream(p, std::ios::binary) << bytes;
  const Volume stored = read_volume(p.string());
  ASSERT_EQ(stored.type(), ScalarType::Int16);
  EXPECT_EQ(std::memcmp(stored.bytes(), v.bytes(), v.byte_size()), 0);
  fs::remove_all(dir);
}

// --- MRC -----------------------------------------------------------------------------------

struct MrcSpec {
  int mode = 2;
  int map[3] = {1, 2, 3};
  int start[3] = {0, 0, 0};
  float origin[3] = {0, 0, 0};
  float cell_scale = 1;  // cell length = n * scale (voxel size = scale with mx = n)
  int nsymbt = 0;
  bool big_endian = false;
  int ispg = 0;
  int mz = 0;           // 0: the volume's z size
  int imod_flags = -1;  // IMOD's stamp with these flags; -1: no stamp
};

template <class T>
void put(std::vector<unsigned char>& b, std::size_t at, T v, bool big) {
  unsigned char x[sizeof(T)];
  std::memcpy(x, &v, sizeof(T));
  if (big) std::reverse(x, x + sizeof(T));
  std::memcpy(b.data() + at, x, sizeof(T));
}

// Writes `v` (X, Y, Z) as an MRC file whose columns, rows and sections run along spec.map.
void write_mrc(const fs::path& path, const Volume& v, const MrcSpec& s) {
  const bool big = s.big_endian;
  std::vector<unsigned char> h(1024 + s.nsymbt, 0);
  std::int64_t n[3];
  for (int c = 0; c < 3; ++c) n[c] = v.dims()[s.map[c] - 1];
  for (int c = 0; c < 3; ++c) put<std::int32_t>(h, 4 * c, static_cast<std::int32_t>(n[c]), big);
  put<std::int32_t>(h, 12, s.mode, big);
  for (int c = 0; c < 3; ++c) put<std::int32_t>(h, 16 + 4 * c, s.start[c], big);
  for (int a = 0; a < 3; ++a)
    put<std::int32_t>(h, 28 + 4 * a, static_cast<std::int32_t>(v.dims()[a]), big);
  if (s.mz) put<std::int32_t>(h, 36, s.mz, big);
  put<std::int32_t>(h, 88, s.ispg, big);
  if (s.imod_flags >= 0) {
    put<std::int32_t>(h, 152, 1146047817, big);  // "IMOD"
    put<std::int32_t>(h, 156, s.imod_flags, big);
  }
  for (int a = 0; a < 3; ++a)
    put<float>(h, 40 + 4 * a, static_cast<float>(v.dims()[a]) * s.cell_scale * (a + 1), big);
  for (int a = 0; a < 3; ++a) put<float>(h, 52 + 4 * a, 90.0f, big);
  for (int c = 0; c < 3; ++c) put<std::int32_t>(h, 64 + 4 * c, s.map[c], big);
  put<std::int32_t>(h, 92, s.nsymbt, big);
  for (int a = 0; a < 3; ++a) put<float>(h, 196 + 4 * a, s.origin[a], big);
  std::memcpy(h.data() + 208, "MAP ", 4);
  h[212] = big ? 0x11 : 0x44;
  h[213] = big ? 0x11 : 0x41;
  const std::size_t size = s.mode == 12 ? 2 : scalar_size(v.type());
  Index3 stride{1, v.dims()[0], v.dims()[0] * v.dims()[1]};
  for (std::int64_t k = 0; k < n[2]; ++k)
    for (std::int64_t j = 0; j < n[1]; ++j)
      for (std::int64_t i = 0; i < n[0]; ++i) {
        const std::int64_t at =
            i * stride[s.map[0] - 1] + j * stride[s.map[1] - 1] + k * stride[s.map[2] - 1];
        unsigned char x[8];
        if (s.mode == 12) {
          // The test fields' half-float values: exact for the integers used here.
          const float f = v.data<float>()[at];
          const auto bits = std::bit_cast<std::uint32_t>(f);
          std::uint16_t half = static_cast<std::uint16_t>(
              ((bits >> 16) & 0x8000) |
              (f == 0 ? 0 : ((((bits >> 23) & 0xff) - 127 + 15) << 10) | ((bits >> 13) & 0x3ff)));
          std::memcpy(x, &half, 2);
        } else {
          std::memcpy(x, v.bytes() + at * size, size);
        }
        if (big) std::reverse(x, x + size);
        h.insert(h.end(), x, x + size);
      }
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(h.data()), static_cast<std::streamsize>(h.size()));
}

TEST(Mrc, AxisOrderStartCellAndOriginFollowMrc2014) {
  const fs::path dir = fs::temp_directory_path() / ("isotile-mrc-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Volume raw = make_field_volume(*parse_field_spec("field:torus:24"));
  const Volume raw16 = field_as("field:torus:24", ScalarType::Int16);
  struct Case {
    const char* name;
    MrcSpec spec;
    const Volume* volume;
  };
  MrcSpec permuted;
  permuted.map[0] = 3, permuted.map[1] = 1, permuted.map[2] = 2;
  permuted.start[0] = -5, permuted.start[1] = 7, permuted.start[2] = 2;
  permuted.origin[0] = 1.5f, permuted.origin[2] = -3;
  permuted.cell_scale = 0.5f;
  permuted.nsymbt = 80;
  MrcSpec big16;
  big16.mode = 1;
  big16.big_endian = true;
  big16.start[2] = -12;
  for (const Case& c : {Case{"plain.mrc", MrcSpec{}, &raw}, Case{"permuted.map", permuted, &raw},
                        Case{"big16.ccp4", big16, &raw16}}) {
    SCOPED_TRACE(c.name);
    const fs::path p = dir / c.name;
    write_mrc(p, *c.volume, c.spec);
    const Volume v = read_volume(p.string());
    ASSERT_EQ(v.dims(), c.volume->dims());
    ASSERT_EQ(v.type(), c.volume->type());
    ASSERT_EQ(std::memcmp(v.bytes(), c.volume->bytes(), v.byte_size()), 0);
    // Start along X, Y, Z: the start fields go with columns, rows, sections.
    Vec3d start{};
    for (int col = 0; col < 3; ++col) start[c.spec.map[col] - 1] = c.spec.start[col];
    for (int a = 0; a < 3; ++a) {
      const double voxel = c.spec.cell_scale * (a + 1);
      EXPECT_NEAR(v.spacing()[a], voxel, 1e-6);
      EXPECT_NEAR(v.origin()[a], c.spec.origin[a] + start[a] * voxel, 1e-5);
    }
    const double iso = iso_for(c.volume->type());
    Mesh m = mc(v.view(), iso);
    apply_frame(mesh_frame(v.view()), m);
    expect_mapped(mc(c.volume->view(), iso), m, v.spacing(), WorldFrame{v.origin(), kIdentity3});
    // In X, Y, Z order and uncompressed: the tiler reads it by region; otherwise whole.
    auto source = open_volume_source(p.string(), {});
    EXPECT_EQ(source->in_memory(), c.spec.map[0] != 1);
  }
  fs::remove_all(dir);
}

TEST(Mrc, HalfFloatsAreWidened) {
  const fs::path dir = fs::temp_directory_path() / ("isotile-mrc12-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  Volume v(ScalarType::Float32, {4, 3, 2});
  for (std::int64_t i = 0; i < v.sample_count(); ++i)
    v.data<float>()[i] = static_cast<float>(i) - 10;
  MrcSpec s;
  s.mode = 12;
  write_mrc(dir / "h.mrc", v, s);
  const Volume r = read_volume((dir / "h.mrc").string());
  ASSERT_EQ(r.type(), ScalarType::Float32);
  for (std::int64_t i = 0; i < v.sample_count(); ++i)
    EXPECT_EQ(r.data<float>()[i], static_cast<float>(i) - 10);
  fs::remove_all(dir);
}

// Mode 0 is signed bytes, unless IMOD's stamp says unsigned (its flags' bit 0 clear), as IMOD
// writes them; a stack of volumes (ISPG 401) is refused, not read as one volume twice as deep.
TEST(Mrc, ImodBytesAndVolumeStacks) {
  const fs::path dir = fs::temp_directory_path() / ("isotile-mrc0-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  Volume v(ScalarType::UInt8, {4, 3, 6});
  for (std::int64_t i = 0; i < v.sample_count(); ++i)
    v.data<std::uint8_t>()[i] = static_cast<std::uint8_t>(i * 7 + 100);
  for (const int flags : {-1, 0, 1}) {
    MrcSpec s;
    s.mode = 0;
    s.imod_flags = flags;
    s.big_endian = flags == 1;
    const fs::path p = dir / ("m" + std::to_string(flags) + ".mrc");
    write_mrc(p, v, s);
    const Volume r = read_volume(p.string());
    EXPECT_EQ(r.type(), flags == 0 ? ScalarType::UInt8 : ScalarType::Int8) << flags;
    ASSERT_EQ(std::memcmp(r.bytes(), v.bytes(), v.byte_size()), 0);  // the same bits either way
    EXPECT_EQ(read_volume_header(p.string()).type, r.type());
  }
  MrcSpec stack;
  stack.mode = 0;
  stack.ispg = 401;
  stack.mz = 3;
  write_mrc(dir / "stack.mrcs", v, stack);
  expect_both_refuse(dir / "stack.mrcs", "an MRC stack of 2 volumes of 3 sections each");
  stack.mz = 6;  // one volume of the stack's space group
  write_mrc(dir / "one.mrcs", v, stack);
  EXPECT_EQ(read_volume((dir / "one.mrcs").string()).dims(), v.dims());
  stack.ispg = 1;  // a volume whose sampling differs from its size
  stack.mz = 3;
  write_mrc(dir / "sampled.mrc", v, stack);
  EXPECT_EQ(read_volume((dir / "sampled.mrc").string()).dims(), v.dims());
  // ISPG 0 named .mrcs (cryo-EM's stacks of particle images): 6 images, not a volume; the same
  // bytes named .mrc are read as a volume.
  stack.ispg = 0;
  stack.mz = 1;
  write_mrc(dir / "particles.MRCS", v, stack);
  expect_both_refuse(dir / "particles.MRCS", "a stack of 6 2-D images (.mrcs, space group ISPG 0)");
  write_mrc(dir / "images.mrc", v, stack);
  EXPECT_EQ(read_volume((dir / "images.mrc").string()).dims(), v.dims());
  fs::remove_all(dir);
}

// NRRD's space directions and origin, RAS turned into LPS as ITK does.
TEST(Nrrd, SpaceDirectionsGiveTheWorldFrame) {
  const fs::path dir = fs::temp_directory_path() / ("isotile-nrrd-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const Volume raw = make_field_volume(*parse_field_spec("field:torus:20"));
  std::ofstream(dir / "t.raw", std::ios::binary)
      .write(reinterpret_cast<const char*>(raw.bytes()),
             static_cast<std::streamsize>(raw.byte_size()));
  std::ofstream(dir / "t.nhdr") << "NRRD0004\ntype: float\ndimension: 3\nsizes: 20 20 20\n"
                                   "space: right-anterior-superior\n"
                                   "space directions: (0,-1,0) (2,0,0) (0,0,1.5)\n"
                                   "space origin: (10,20,30)\nendian: little\nencoding: raw\n"
                                   "data file: t.raw\n\n";
  const Volume v = read_volume((dir / "t.nhdr").string());
  EXPECT_EQ(v.spacing(), (Vec3d{1, 2, 1.5}));
  EXPECT_EQ(v.origin(), (Vec3d{10, 20, 30}));  // the grid frame: as before
  ASSERT_TRUE(v.world());
  EXPECT_EQ(v.world()->origin, (Vec3d{-10, -20, 30}));
  // Columns: axis 0 towards RAS -y = LPS +y, axis 1 towards RAS +x = LPS -x, axis 2 +z.
  EXPECT_EQ(v.world()->direction, (Mat3{0, -1, 0, 1, 0, 0, 0, 0, 1}));
  Mesh m = mc(v.view(), 0);
  apply_frame(mesh_frame(v.view()), m);
  expect_mapped(mc(raw.view(), 0), m, v.spacing(), *v.world());
  auto source = open_volume_source((dir / "t.nhdr").string(), {});
  EXPECT_EQ(source->world->direction, v.world()->direction);
  fs::remove_all(dir);
}

// --- real files ------------------------------------------------------------------------------

const char* kDicomUid = "1.2.156.112605.14038013508437.20180925052418.3.14156.1";

TEST(RealData, DicomSeriesGeometryFromItsHeaders) {
  REQUIRE_ITK();
  const fs::path dir = testing::shared_volume("dicom_uih_t1_head_slab");
  ISOTILE_REQUIRE_SHARED(dir);
  // Expected values from the series' SOURCE.txt (measured with pydicom, not with isotile).
  const VolumeHeader h = read_volume_header(dir.string());
  EXPECT_EQ(h.format, "DICOM");
  EXPECT_EQ(h.type, ScalarType::UInt16);
  EXPECT_EQ(h.dims, (Index3{460, 512, 80}));
  EXPECT_NEAR(h.spacing[0], 0.5, 1e-9);
  EXPECT_NEAR(h.spacing[1], 0.5, 1e-9);
  EXPECT_NEAR(h.spacing[2], 1.0, 1e-4);
  EXPECT_EQ(h.series_uid, kDicomUid);
  EXPECT_EQ(h.series_description, "t1_gre_fsp_3d_sag");
  ASSERT_TRUE(h.world);
  const Mat3& d = h.world->direction;
  // Rows along ImageOrientationPatient's first vector, columns along its second, slices along
  // the normal; the first slice along the normal is 00000120.dcm at x = +25.50.
  EXPECT_NEAR(d[0], 0.0679929852, 1e-6);
  EXPECT_NEAR(d[3], 0.99768579, 1e-6);
  EXPECT_NEAR(d[7], -1, 1e-9);
  EXPECT_NEAR(d[2], -0.998, 1e-3);
  EXPECT_NEAR(d[5], 0.068, 1e-3);
  EXPECT_NEAR(h.world->origin[0], 25.50, 0.01);
  // Any file of the series reads the series.
  const VolumeHeader one = read_volume_header((dir / "00000077.dcm").string());
  EXPECT_EQ(one.dims, h.dims);
  EXPECT_EQ(one.world->origin, h.world->origin);
  const Volume v = read_volume(dir.string());
  EXPECT_EQ(value_range(v.view()), (std::pair<double, double>{0, 939}));
}

TEST(RealData, TiffStackWithImageJTags) {
  REQUIRE_ITK();
  const fs::path file = testing::shared_volume("tiff_arabidopsis_embryo/arabidopsis-embryo.tif");
  ISOTILE_REQUIRE_SHARED(file);
  const Volume v = read_volume(file.string());
  EXPECT_EQ(v.dims(), (Index3{109, 112, 106}));
  EXPECT_EQ(v.type(), ScalarType::UInt8);
  EXPECT_EQ(value_range(v.view()), (std::pair<double, double>{0, 255}));
  // ImageJ stores the pages' samples one after another: read by region, the same samples.
  auto source = open_volume_source(file.string(), {});
  EXPECT_FALSE(source->in_memory());
  std::vector<std::byte> all(v.byte_size());
  source->read({{0, 0, 0}, v.dims()}, all.data());
  EXPECT_EQ(std::memcmp(all.data(), v.bytes(), v.byte_size()), 0);
}

// Copies of a few slices of the real series in a directory of the test's own.
class DicomDir : public CliTest {
 protected:
  fs::path series_ = testing::shared_volume("dicom_uih_t1_head_slab");
  // `shift_z` moves the slice's ImagePositionPatient along z (within the slice's plane here: its
  // columns run along -z) by whole millimetres, keeping the value's length.
  void copy(int number, const std::string& as = "", bool other_series = false, int shift_z = 0) {
    char name[32];
    std::snprintf(name, sizeof name, "%08d.dcm", number);
    ASSERT_TRUE(fs::is_regular_file(series_ / name)) << name;  // the series holds 41 to 120
    std::string bytes = testing::slurp(series_ / name);
    if (shift_z != 0) {
      const std::size_t tag =
          bytes.find(std::string("\x20\x00\x32\x00"
                                 "DS",
                                 6));
      ASSERT_NE(tag, std::string::npos);
      const std::size_t length =
          static_cast<unsigned char>(bytes[tag + 6]) |
          static_cast<std::size_t>(static_cast<unsigned char>(bytes[tag + 7])) << 8;
      std::string value = bytes.substr(tag + 8, length);
      const std::size_t z = value.rfind('\\') + 1;
      const double moved = std::stod(value.substr(z)) + shift_z;
      std::string text = std::to_string(moved).substr(0, value.size() - z);
      text.resize(value.size() - z, ' ');
      value.replace(z, std::string::npos, text);
      bytes.replace(tag + 8, length, value);
    }
    if (other_series) {
      // Same length, another UID: a second series in the directory.
      const std::string uid = kDicomUid;
      for (std::size_t at = bytes.find(uid); at != std::string::npos; at = bytes.find(uid, at + 1))
        bytes[at + uid.size() - 1] = '2';
    }
    std::ofstream(dir_ / (as.empty() ? name : as), std::ios::binary) << bytes;
  }
};

TEST_F(DicomDir, SeveralSeriesAreListedAndOneIsChosen) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  for (int n = 50; n < 54; ++n) copy(n);
  for (int n = 60; n < 63; ++n) copy(n, "", true);
  const std::string other = std::string(kDicomUid).substr(0, std::strlen(kDicomUid) - 1) + "2";
  CliResult r = run("extract . -o out.ply --iso 60 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("2 DICOM series; choose one with --series"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(other), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  r = run("info . --json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("t1_gre_fsp_3d_sag"), std::string::npos);
  r = run("info . --json --series " + other);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("\"dims\": [\n    460,\n    512,\n    3\n  ]"), std::string::npos) << r.out;
  // The real series' info: orientation letters from SOURCE.txt's ImageOrientationPatient (rows
  // towards +y: P, columns towards -z: I, the normal towards -x: R), its value range.
  r = run("info '" + series_.string() + "' --json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("\"orientation\": \"PIR\""), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"format\": \"DICOM\""), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"max\": 939.0"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"rescaled\": false"), std::string::npos) << r.out;
  r = run("extract . -o out.ply --iso 60 -q --series 1.2.3");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("no DICOM series with UID 1.2.3"), std::string::npos) << r.err;
}

TEST_F(DicomDir, UnevenOrDuplicateSlicesAreErrors) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  copy(50);
  copy(51);
  copy(53);  // 52 missing: a 2 mm step among 1 mm steps
  CliResult r = run("extract . -o out.ply --iso 60 -q");
  EXPECT_EQ(r.code, 1);
  // The gap is named by the files on either side and its size against the typical step.
  EXPECT_NE(
      r.err.find("a gap of 2 mm between slices 00000053.dcm and 00000051.dcm where the slices "
                 "lie "
                 "1 mm apart (about 1 slice missing)"),
      std::string::npos)
      << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  fs::remove(dir_ / "00000053.dcm");
  copy(51, "copy_of_51.dcm");
  r = run("extract . -o out.ply --iso 60 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("lie at the same position"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
  // Among more slices (GDCM gives up sorting the series, so neighbours in its order are others):
  // the two files at one position named, on one line (GDCM's own multi-line errors silenced).
  for (int n = 52; n < 60; ++n) copy(n);
  r = run("info .");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("lie at the same position"), std::string::npos) << r.err;
  for (const char* name : {"00000051.dcm", "copy_of_51.dcm"})
    EXPECT_NE(r.err.find(name), std::string::npos) << name << ": " << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  // A folder without a series: one line, ITK's warnings silenced.
  fs::create_directory(dir_ / "empty");
  r = run("info empty");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("empty: no DICOM series found"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// One slice whose position moves across the normal, the first and the last on the stack's axis:
// named (only the last slice's position was compared, and the slice was stacked in place).
// Every slice's PixelSpacing must be the first's (GDCM stacks them at the first's: half a series
// at another scale came out at it, exit 0), and none may be 0 (GDCM takes 1 mm for it).
TEST_F(DicomDir, PixelSpacingsThatDifferOrAreZeroAreRefused) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  const auto set_spacing = [&](int number, const std::string& value) {
    char name[32];
    std::snprintf(name, sizeof name, "%08d.dcm", number);
    std::string bytes = testing::slurp(dir_ / name);
    const std::size_t tag =
        bytes.find(std::string("\x28\x00\x30\x00"
                               "DS\x08\x00",
                               8));
    ASSERT_NE(tag, std::string::npos);
    ASSERT_EQ(value.size(), 8u);
    bytes.replace(tag + 8, 8, value);
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
  };
  const auto error_of = [](const auto& read) {
    try {
      read();
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("(read)");
  };
  for (int n = 50; n < 55; ++n) copy(n);
  ASSERT_EQ(read_volume_header(dir_.string()).spacing[0], 0.5);
  set_spacing(52, "0.9\\0.9 ");
  for (const bool header : {true, false}) {
    const std::string msg = error_of([&] {
      if (header)
        read_volume_header(dir_.string());
      else
        read_volume(dir_.string());
    });
    EXPECT_NE(msg.find("00000052.dcm: pixel spacing 0.9 x 0.9 where "), std::string::npos) << msg;
    EXPECT_NE(msg.find("one volume needs it alike in every slice"), std::string::npos) << msg;
  }
  for (int n = 50; n < 55; ++n) set_spacing(n, "0\\0.5   ");
  std::string msg = error_of([&] { read_volume_header(dir_.string()); });
  EXPECT_NE(msg.find("PixelSpacing (0028,0030) holds '0\\0.5'; a pixel spacing is two positive"),
            std::string::npos)
      << msg;
  // A 0 in a later slice alone: GDCM's 1 mm for it matched a first slice of 1 mm, exit 0.
  for (int n = 50; n < 55; ++n) set_spacing(n, n == 53 ? "1\\0     " : "1\\1     ");
  for (const bool header : {true, false}) {
    msg = error_of([&] {
      if (header)
        read_volume_header(dir_.string());
      else
        read_volume(dir_.string());
    });
    EXPECT_NE(msg.find("00000053.dcm: PixelSpacing (0028,0030) holds '1\\0'; a pixel spacing"),
              std::string::npos)
        << msg;
  }
}

// MONOCHROME1: ITK's reader inverts the stored values (to MONOCHROME2) before the rescale, so the
// samples are not in the file's units (-1024 HU came out as 64511): refused, not meshed, in any
// slice of a series.
TEST_F(DicomDir, Monochrome1IsRefused) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  const auto set_photometric = [&](int n, const char* value) {
    char name[32];
    std::snprintf(name, sizeof name, "%08d.dcm", n);
    std::string bytes = testing::slurp(dir_ / name);
    const std::size_t at = bytes.find("MONOCHROME2");
    ASSERT_NE(at, std::string::npos);
    bytes.replace(at, 11, value);
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
  };
  for (int n = 50; n < 54; ++n) {
    copy(n);
    set_photometric(n, "MONOCHROME1");
  }
  try {
    read_volume_header(dir_.string());
    ADD_FAILURE() << "read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("PhotometricInterpretation MONOCHROME1"),
              std::string::npos)
        << e.what();
  }
  // One MONOCHROME1 slice among MONOCHROME2 ones: ITK reads each slice by itself, and that one
  // came out inverted, exit 0.
  for (int n = 50; n < 54; ++n) copy(n);
  set_photometric(52, "MONOCHROME1");
  for (const char* command : {"info .", "extract . -o out.ply --iso 60 -q",
                              "extract . -o out.ply --iso 60 -q --memory 8MiB"}) {
    const CliResult r = run(command);
    EXPECT_EQ(r.code, 1) << command;
    EXPECT_NE(r.err.find("00000052.dcm: PhotometricInterpretation MONOCHROME1"), std::string::npos)
        << command << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << command;
  }
}

TEST_F(DicomDir, ASliceOffTheStacksAxisIsNamed) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  for (int n = 50; n < 56; ++n) copy(n, "", false, n == 52 ? 3 : 0);
  const CliResult r = run("extract . -o out.ply --iso 60 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("slice 00000052.dcm lies 3 mm across the stack's axis"), std::string::npos)
      << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
  // In place again, the series reads.
  copy(52);
  EXPECT_EQ(run("extract . -o out.ply --iso 60 -q").code, 0);
}

// An entry GDCM cannot open beside the slices (a dangling link, a FIFO) is named; it made GDCM's
// sorting give up and the slices were reported as missing ("a gap of 18 mm ... about 1 slice
// missing"). A subfolder is not part of the series and is passed over.
TEST_F(DicomDir, AnEntryThatIsNotAFileIsNamed) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  for (int n = 41; n < 60; ++n) copy(n);
  fs::create_directory(dir_ / "sub");
  ASSERT_EQ(run("info . --json").code, 0);
  fs::create_symlink("nowhere", dir_ / "zz_dangling");
  CliResult r = run("info .");
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err,
            "isotile: error: ./zz_dangling: a link to nothing in the DICOM folder; remove "
            "it (a folder's files are read as one series)\n");
  fs::remove(dir_ / "zz_dangling");
  ASSERT_EQ(::mkfifo((dir_ / "zz_fifo").c_str(), 0600), 0);
  r = run("extract . -o out.ply --iso 60 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("zz_fifo: not a regular file (a FIFO, socket or device)"), std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
}

// The real series in core and out of core: the same bytes, in world coordinates.
TEST_F(DicomDir, WorldMeshInCoreEqualsStreamed) {
  REQUIRE_ITK();
  ISOTILE_REQUIRE_SHARED(series_);
  for (int n = 60; n < 72; ++n) copy(n);
  CliResult r = run("extract . -o a.ply --iso 60 --normals -q --stats a.json");
  ASSERT_EQ(r.code, 0) << r.err;
  r = run("extract . -o b.ply --iso 60 --normals -q --memory 8MiB --threads 1 --stats b.json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(testing::slurp(dir_ / "a.ply"), testing::slurp(dir_ / "b.ply"));
  EXPECT_NE(testing::slurp(dir_ / "b.json").find("\"region_reads\": false"), std::string::npos);
  r = run("extract . -o g.ply --iso 60 -q --frame grid");
  ASSERT_EQ(r.code, 0) << r.err;
  // The world mesh is the grid mesh turned by the series' ImageOrientationPatient (SOURCE.txt):
  // grid x along the row vector, grid y along the column vector, grid z along their normal.
  const Mesh world = read_mesh(dir_ / "a.ply"), grid = read_mesh(dir_ / "g.ply");
  ASSERT_EQ(world.positions.size(), grid.positions.size());
  ASSERT_GT(world.positions.size(), 1000u);
  const Vec3d row{0.0679929852, 0.99768579, 0}, col{0, 0, -1};
  const Vec3d normal{row[1] * col[2] - row[2] * col[1], row[2] * col[0] - row[0] * col[2],
                     row[0] * col[1] - row[1] * col[0]};
  double worst = 0;
  for (std::size_t i = 1; i < world.positions.size(); ++i) {
    Vec3d dw, dg;
    for (int a = 0; a < 3; ++a) {
      dw[a] = world.positions[i][a] - world.positions[0][a];
      dg[a] = grid.positions[i][a] - grid.positions[0][a];
    }
    const auto dot = [](const Vec3d& a, const Vec3d& b) {
      return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    };
    worst = std::max({worst, std::abs(dot(dw, row) - dg[0]), std::abs(dot(dw, col) - dg[1]),
                      std::abs(dot(dw, normal) - dg[2])});
  }
  EXPECT_LT(worst, 1e-3);
}

// DICOM files written element by element (tests/dicom_bytes.h), 12 columns x 16 rows of uint16,
// pixel spacing 0.7 between rows and 0.3 between columns. Enhanced MR: each frame placed by its
// own PlanePositionSequence, the orientation and the pixel spacing in the shared functional
// group; GDCM places such frames by the step between the first two and falls back to a spacing
// of 1, 1, 1 where the steps differ; isotile places them itself and checks them as a series'
// slices. MR slices: one frame each, its geometry at the top level.
class DicomFiles : public CliTest {
 protected:
  static constexpr int kColumns = 12, kRows = 16;
  const Vec3d row_{0.0679929852, 0.99768579, 0}, column_{0, 0, -1};
  const Vec3d normal_ = cross(row_, column_);
  const Vec3d first_{-53.3, -112.7, 126.1};

  // The position `along` millimetres from the first frame's along the normal (and `across`
  // millimetres along the columns).
  Vec3d at(double along, double across = 0) const {
    Vec3d p;
    for (int c = 0; c < 3; ++c) p[c] = first_[c] + along * normal_[c] + across * column_[c];
    return p;
  }
  static std::string position(const Vec3d& p) {
    return testing::dicom::element(0x0020, 0x0032, "DS", testing::dicom::ds({p[0], p[1], p[2]}));
  }
  // Frame content `c`: a background of 10 * (c + 1) and, on contents 1 to 3, a block of 1000
  // (rows 3 to 9, columns 2 to 5): each frame is known by its samples.
  static std::uint16_t sample(int c, int row, int column) {
    const bool block = c >= 1 && c <= 3 && row >= 3 && row <= 9 && column >= 2 && column <= 5;
    return static_cast<std::uint16_t>(block ? 1000 : 10 * (c + 1));
  }
  static std::string pixels(const std::vector<int>& contents) {
    std::string out;
    for (int c : contents)
      for (int r = 0; r < kRows; ++r)
        for (int col = 0; col < kColumns; ++col) out += testing::dicom::u16(sample(c, r, col));
    return testing::dicom::element(0x7FE0, 0x0010, "OW", out);
  }
  // The elements up to the geometry: SOP class and instance, modality, study, series, number.
  static std::string identity(const std::string& sop_class, const std::string& sop,
                              const char* modality, const std::string& series,
                              const std::string& number) {
    using testing::dicom::element;
    return element(0x0008, 0x0016, "UI", sop_class) + element(0x0008, 0x0018, "UI", sop) +
           element(0x0008, 0x0060, "CS", modality) +
           element(0x0020, 0x000D, "UI", "1.2.826.0.1.3680043.2.1.5") +
           element(0x0020, 0x000E, "UI", series) + element(0x0020, 0x0013, "IS", number);
  }
  // The pixel description of `frames` frames (none written where 0) of unsigned 16-bit samples,
  // with PixelSpacing `spacing` where not empty, and `more` (elements of group 0028 up to 0028,
  // 0009, in tag order) after NumberOfFrames.
  static std::string pixel_module(std::size_t frames, const std::string& spacing,
                                  const std::string& more = "") {
    using testing::dicom::element;
    using testing::dicom::u16;
    return element(0x0028, 0x0002, "US", u16(1)) + element(0x0028, 0x0004, "CS", "MONOCHROME2") +
           (frames ? element(0x0028, 0x0008, "IS", std::to_string(frames)) : "") + more +
           element(0x0028, 0x0010, "US", u16(kRows)) +
           element(0x0028, 0x0011, "US", u16(kColumns)) +
           (spacing.empty() ? "" : element(0x0028, 0x0030, "DS", spacing)) +
           element(0x0028, 0x0100, "US", u16(16)) + element(0x0028, 0x0101, "US", u16(16)) +
           element(0x0028, 0x0102, "US", u16(15)) + element(0x0028, 0x0103, "US", u16(0));
  }
  // An Enhanced MR file: frame k holds content `contents[k]` at `positions[k]` (none where
  // `positions` is empty); `per_frame(k)` adds elements to frame k's functional group after its
  // PlanePositionSequence (in tag order). Files of one series differ by `instance`.
  void write(const std::string& name, const std::vector<int>& contents,
             const std::vector<Vec3d>& positions,
             const std::function<std::string(std::size_t)>& per_frame = {},
             const std::string& instance = "1") const {
    using testing::dicom::element;
    using testing::dicom::sequence;
    std::vector<std::string> frames;
    for (std::size_t k = 0; k < contents.size(); ++k)
      frames.push_back(
          (positions.empty() ? "" : sequence(0x0020, 0x9113, {position(positions[k])})) +
          (per_frame ? per_frame(k) : ""));
    const std::string sop_class = "1.2.840.10008.5.1.4.1.1.4.1",
                      sop = "1.2.826.0.1.3680043.2.1.7." + instance;
    const std::string shared =
        sequence(0x0020, 0x9116, {orientation()}) +
        sequence(0x0028, 0x9110, {element(0x0028, 0x0030, "DS", "0.7\\0.3")});
    const std::string body = identity(sop_class, sop, "MR", "1.2.826.0.1.3680043.2.1.6", instance) +
                             pixel_module(contents.size(), "") +
                             sequence(0x5200, 0x9229, {shared}) + sequence(0x5200, 0x9230, frames) +
                             pixels(contents);
    std::ofstream(dir_ / name, std::ios::binary) << testing::dicom::part10(sop_class, sop, body);
  }
  // One slice of content `c` at `where` (none where empty): MR with its PixelSpacing where
  // `spacing`, and RescaleSlope `slope` where not 0; or, `ct_imager`, CT whose only pixel
  // spacing is ImagerPixelSpacing (a projection's, which GDCM does not read for CT);
  // ImageOrientationPatient with its column turned by `turn` (none where empty).
  void write_slice(const std::string& name, int c, const std::optional<Vec3d>& where,
                   bool spacing = true, int slope = 0, bool ct_imager = false,
                   std::optional<double> turn = 0.0) const {
    using testing::dicom::element;
    const std::string sop_class =
                          ct_imager ? "1.2.840.10008.5.1.4.1.1.2" : "1.2.840.10008.5.1.4.1.1.4",
                      sop = "1.2.826.0.1.3680043.2.1.8." + std::to_string(c + 1);
    const std::string body = identity(sop_class, sop, ct_imager ? "CT" : "MR",
                                      "1.2.826.0.1.3680043.2.1.9", std::to_string(c + 1)) +
                             (ct_imager ? element(0x0018, 0x1164, "DS", "0.7\\0.3") : "") +
                             (where ? position(*where) : "") + (turn ? orientation(*turn) : "") +
                             pixel_module(0, spacing && !ct_imager ? "0.7\\0.3" : "") +
                             (slope ? element(0x0028, 0x1052, "DS", "0") +
                                          element(0x0028, 0x1053, "DS", std::to_string(slope))
                                    : "") +
                             pixels({c});
    std::ofstream(dir_ / name, std::ios::binary) << testing::dicom::part10(sop_class, sop, body);
  }
  // An RT Dose file: frame k holds content `contents[k]` `offsets[k]` mm along the normal from
  // the first frame's position (GridFrameOffsetVector, relative: the first is 0).
  void write_dose(const std::string& name, const std::vector<int>& contents,
                  const std::vector<double>& offsets) const {
    using testing::dicom::element;
    const std::string sop_class = "1.2.840.10008.5.1.4.1.1.481.2",
                      sop = "1.2.826.0.1.3680043.2.1.10.1";
    const std::string body =
        identity(sop_class, sop, "RTDOSE", "1.2.826.0.1.3680043.2.1.11", "1") + position(first_) +
        orientation() +
        pixel_module(contents.size(), "0.7\\0.3",
                     element(0x0028, 0x0009, "AT",
                             testing::dicom::u16(0x3004) + testing::dicom::u16(0x000C))) +
        element(0x3004, 0x000C, "DS", testing::dicom::ds(offsets)) + pixels(contents);
    std::ofstream(dir_ / name, std::ios::binary) << testing::dicom::part10(sop_class, sop, body);
  }
  // A multi-frame file of class `sop_class` whose frames have no positions of their own: one
  // ImagePositionPatient (the first frame's) and PixelSpacing for all; FrameIncrementPointer
  // naming `pointer` (group, element pairs) where not empty; `more` (further elements).
  void write_frames(const std::string& name, const std::string& sop_class, const char* modality,
                    const std::vector<int>& contents,
                    const std::vector<std::pair<std::uint16_t, std::uint16_t>>& pointer,
                    const std::string& more) const {
    using testing::dicom::element;
    using testing::dicom::u16;
    std::string named;
    for (const auto& [group, elem] : pointer) named += u16(group) + u16(elem);
    const std::string sop = "1.2.826.0.1.3680043.2.1.12.1";
    const std::string body =
        identity(sop_class, sop, modality, "1.2.826.0.1.3680043.2.1.13", "1") + position(first_) +
        orientation() +
        pixel_module(contents.size(), "0.7\\0.3",
                     named.empty() ? "" : element(0x0028, 0x0009, "AT", named)) +
        more + pixels(contents);
    std::ofstream(dir_ / name, std::ios::binary) << testing::dicom::part10(sop_class, sop, body);
  }
  // ImageOrientationPatient, its column turned by `turn` (towards x).
  std::string orientation(double turn = 0) const {
    return testing::dicom::element(
        0x0020, 0x0037, "DS",
        testing::dicom::ds({row_[0], row_[1], row_[2], column_[0] + turn, column_[1], column_[2]}));
  }
  // The volume read from `name`: z plane k must hold frame content `contents[k]`.
  void expect_volume(const std::string& name, const std::vector<int>& contents,
                     const Vec3d& origin) const {
    const Volume v = read_volume((dir_ / name).string());
    ASSERT_EQ(v.dims(), (Index3{kColumns, kRows, static_cast<std::int64_t>(contents.size())}));
    EXPECT_NEAR(v.spacing()[0], 0.3, 1e-9);
    EXPECT_NEAR(v.spacing()[1], 0.7, 1e-9);
    EXPECT_NEAR(v.spacing()[2], 1.5, 1e-6);
    ASSERT_TRUE(v.world());
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(v.world()->origin[c], origin[c], 1e-6) << c;
      EXPECT_NEAR(v.world()->direction[3 * c], row_[c], 1e-6) << c;
      EXPECT_NEAR(v.world()->direction[3 * c + 1], column_[c], 1e-6) << c;
      EXPECT_NEAR(v.world()->direction[3 * c + 2], normal_[c], 1e-6) << c;
    }
    const auto* s = v.view().typed<std::uint16_t>();
    for (std::size_t k = 0; k < contents.size(); ++k)
      for (int r = 0; r < kRows; ++r)
        for (int col = 0; col < kColumns; ++col)
          ASSERT_EQ(s[(k * kRows + r) * kColumns + col], sample(contents[k], r, col))
              << "z " << k << " row " << r << " column " << col;
  }
  std::string refusal(const std::string& name) {
    const CliResult r = run("extract " + name + " -o out.ply --iso 500 -q");
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
    return r.err;
  }
};

// Frames in any order along the normal are read in that order, with their own spacing and the
// origin of the first along it; the same mesh as the frames stored in order. GDCM refused frames
// descending along the normal ("spacing -1.5") and read shuffled ones with a spacing of 1, 1, 1.
TEST_F(DicomFiles, FramesArePlacedByTheirPositions) {
  REQUIRE_ITK();
  const std::vector<int> contents{0, 1, 2, 3, 4, 5};
  std::vector<Vec3d> up;
  for (int k = 0; k < 6; ++k) up.push_back(at(1.5 * k));
  write("up.dcm", contents, up);
  expect_volume("up.dcm", contents, first_);
  std::vector<Vec3d> down;
  for (int k = 0; k < 6; ++k) down.push_back(at(1.5 * (5 - k)));
  write("down.dcm", {5, 4, 3, 2, 1, 0}, down);
  expect_volume("down.dcm", contents, first_);
  write("shuffled.dcm", {0, 2, 1, 5, 3, 4}, {at(0), at(3), at(1.5), at(7.5), at(4.5), at(6)});
  expect_volume("shuffled.dcm", contents, first_);
  // In the real program: the three meshes are one, in world coordinates.
  std::vector<std::string> meshes;
  for (const char* name : {"up", "down", "shuffled"}) {
    const CliResult r =
        run(std::string("extract ") + name + ".dcm -o " + name + ".ply --iso 500 -q");
    ASSERT_EQ(r.code, 0) << r.err;
    meshes.push_back(testing::slurp(dir_ / (std::string(name) + ".ply")));
  }
  EXPECT_GT(meshes[0].size(), 1000u);
  EXPECT_EQ(meshes[0], meshes[1]);
  EXPECT_EQ(meshes[0], meshes[2]);
}

// Frames that one volume cannot hold without resampling are refused, each named; GDCM read them
// all with a spacing of 1, 1, 1 (or its first step), a wrong mesh with exit 0.
TEST_F(DicomFiles, FramesThatDoNotStackEvenlyAreRefused) {
  REQUIRE_ITK();
  const std::vector<int> six{0, 1, 2, 3, 4, 5};
  write("gap.dcm", six, {at(0), at(1.5), at(3), at(6), at(7.5), at(9)});
  EXPECT_NE(refusal("gap.dcm").find("gap.dcm: a gap of 3 mm between frames 3 and 4 where the "
                                    "frames lie 1.5 mm apart (about 1 frame missing)"),
            std::string::npos);
  write("uneven.dcm", six, {at(0), at(1.5), at(3), at(4.8), at(6.3), at(7.8)});
  EXPECT_NE(refusal("uneven.dcm").find("non-uniform frame spacing: 1.8 mm between frames 3 and 4"),
            std::string::npos);
  // Two echoes at each position.
  write("echoes.dcm", six, {at(0), at(0), at(1.5), at(1.5), at(3), at(3)});
  EXPECT_NE(refusal("echoes.dcm").find("frames 1 and 2 lie at the same position"),
            std::string::npos);
  std::vector<Vec3d> tilted, bent;
  for (int k = 0; k < 6; ++k) {
    tilted.push_back(at(1.5 * k, 0.3 * k));
    bent.push_back(at(1.5 * k, k == 2 ? 2 : 0));
  }
  write("tilted.dcm", six, tilted);
  EXPECT_NE(refusal("tilted.dcm")
                .find("the frames are not stacked along their normal (gantry tilt "
                      "of 11.3"),
            std::string::npos);
  write("bent.dcm", six, bent);
  EXPECT_NE(refusal("bent.dcm").find("frame 3 lies 2 mm across the stack's axis"),
            std::string::npos);
  std::vector<Vec3d> up;
  for (int k = 0; k < 6; ++k) up.push_back(at(1.5 * k));
  // A frame turned, or rescaled, unlike the others: GDCM takes the first frame's for all.
  write("turned.dcm", six, up, [&](std::size_t k) {
    return k == 3 ? testing::dicom::sequence(0x0020, 0x9116, {orientation(0.05)}) : "";
  });
  EXPECT_NE(refusal("turned.dcm").find("frame 4's ImageOrientationPatient differs from frame 1's"),
            std::string::npos);
  write("rescaled.dcm", six, up, [&](std::size_t k) {
    return testing::dicom::sequence(
        0x0028, 0x9145,
        {testing::dicom::element(0x0028, 0x1052, "DS", "0") +
         testing::dicom::element(0x0028, 0x1053, "DS", k == 1 ? "2" : "1")});
  });
  EXPECT_NE(refusal("rescaled.dcm").find("frame 2's RescaleSlope differs from frame 1's"),
            std::string::npos);
}

// A slice without a position was placed at 0, 0, 0 by GDCM and reported as a gap of 45 mm (or,
// none with one, as slices at one position); a series without PixelSpacing was read with 1 mm
// pixels (GDCM's warning unseen): a mesh of made-up size. Both are named; --spacing reads the
// latter.
TEST_F(DicomFiles, ASliceWithoutPositionOrSpacingIsNamed) {
  REQUIRE_ITK();
  for (int k = 0; k < 4; ++k)
    write_slice("s" + std::to_string(k) + ".dcm", k,
                k == 2 ? std::nullopt : std::optional(at(1.5 * k)));
  EXPECT_NE(refusal(".").find("s2.dcm: no ImagePositionPatient (0020,0032); the slices of a "
                              "series cannot be placed without it"),
            std::string::npos);
  for (int k = 0; k < 4; ++k) write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k), false);
  EXPECT_NE(refusal(".").find("s0.dcm: no PixelSpacing (0028,0030), the element GDCM reads this "
                              "kind of image's pixel spacing from, so the distance between its "
                              "pixels is unknown; give the spacing with --spacing X,Y,Z (the "
                              "slices lie 1.5 mm apart)"),
            std::string::npos);
  CliResult r = run("info . --json --spacing 0.3,0.7,1.5");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("\"spacing\": [\n    0.3,\n    0.7,\n    1.5\n  ]"), std::string::npos)
      << r.out;
  for (int k = 0; k < 4; ++k) write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k));
  expect_volume(".", {0, 1, 2, 3}, first_);
  // CT's is PixelSpacing: ImagerPixelSpacing alone (a projection's) GDCM does not read for CT,
  // and took 1 mm; the element GDCM wants is named.
  for (int k = 0; k < 4; ++k)
    write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k), false, 0, true);
  EXPECT_NE(refusal(".").find("s0.dcm: no PixelSpacing (0028,0030), the element GDCM reads"),
            std::string::npos);
  // Without an orientation, or with a column that leans off the row, the slices cannot be
  // ordered: named so (both were "slices s0.dcm and s1.dcm lie at the same position").
  for (int k = 0; k < 4; ++k)
    write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k), true, 0, false, std::nullopt);
  EXPECT_NE(refusal(".").find("s0.dcm: no ImageOrientationPatient (0020,0037); the slices of a "
                              "series cannot be ordered without it"),
            std::string::npos)
      << refusal(".");
  for (int k = 0; k < 4; ++k)
    write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k), true, 0, false, 0.1);
  EXPECT_NE(refusal(".").find("s0.dcm: ImageOrientationPatient (0020,0037) is not two unit "
                              "vectors at right angles (row and column lengths 1 and 1.00499"),
            std::string::npos)
      << refusal(".");
}

// A slice cut short (empty, or a few bytes of its header) is a file GDCM's scan of the folder
// passes by: at either end of the series the volume was read a slice short, exit 0 (in the middle
// it was called a gap). Refused, naming it, where it is named as DICOM or is empty without an
// extension; other files beside the series (a README) are still passed by.
TEST_F(DicomFiles, ASliceCutShortIsNamedNotLeftOut) {
  REQUIRE_ITK();
  for (int k = 0; k < 4; ++k) write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k));
  std::ofstream(dir_ / "README") << "four slices\n";
  expect_volume(".", {0, 1, 2, 3}, first_);
  for (const std::string name : {"s3.dcm", "s0.dcm"}) {
    for (const std::uintmax_t size : {0, 100}) {
      fs::resize_file(dir_ / name, size);
      for (const std::string input : {".", "s1.dcm"}) {
        const std::string err = refusal(input);
        EXPECT_NE(
            err.find(name + ": named as DICOM but no DICOM data set GDCM reads in a folder (" +
                     std::to_string(size) + " bytes): a slice cut short?"),
            std::string::npos)
            << input << ": " << err;
      }
    }
    write_slice(name, name == "s0.dcm" ? 0 : 3, at(name == "s0.dcm" ? 0 : 4.5));
  }
  fs::rename(dir_ / "s3.dcm", dir_ / "IM3");
  expect_volume(".", {0, 1, 2, 3}, first_);
  fs::resize_file(dir_ / "IM3", 0);
  EXPECT_NE(refusal(".").find("IM3: an empty file in the DICOM series' folder: a slice cut short?"),
            std::string::npos)
      << refusal(".");
  fs::remove(dir_ / "IM3");
  expect_volume(".", {0, 1, 2}, first_);
  // A slice that cannot be read (only where the tests run as another user than root, whom a
  // file's mode does not stop).
  if (::geteuid() != 0) {
    fs::permissions(dir_ / "s2.dcm", fs::perms::none);
    EXPECT_NE(refusal(".").find("s2.dcm: Permission denied (a file in the DICOM series' folder"),
              std::string::npos)
        << refusal(".");
    fs::permissions(dir_ / "s2.dcm", fs::perms::owner_read | fs::perms::owner_write);
  }
}

// Positions written with two decimals (0.625 mm slices: 0, 0.63, 1.25, 1.88, ...) are even: each
// within 0.005 mm of its place. Judged step by step within 0.1% they were refused ("non-uniform
// slice spacing: 0.62 mm ... where the slices lie 0.63 mm apart"); a slice 3% of a step out of
// place still is.
TEST_F(DicomFiles, PositionsWrittenWithTwoDecimalsAreEven) {
  REQUIRE_ITK();
  const auto hundredths = [](Vec3d p) {
    for (double& c : p) c = std::round(c * 100) / 100;
    return p;
  };
  for (int k = 0; k < 8; ++k)
    write_slice("s" + std::to_string(k) + ".dcm", k % 4, hundredths(at(0.625 * k)));
  const Volume v = read_volume(dir_.string());
  EXPECT_EQ(v.dims()[2], 8);
  EXPECT_NEAR(v.spacing()[2], 0.625, 0.002);
  // Written exactly, a slice 1.9% of a step from its place is within the limit, one 3% from it
  // is not.
  for (int k = 0; k < 8; ++k) write_slice("s" + std::to_string(k) + ".dcm", k % 4, at(0.625 * k));
  write_slice("s5.dcm", 1, at(0.625 * 5 + 0.0119));
  EXPECT_EQ(read_volume(dir_.string()).dims()[2], 8);
  write_slice("s5.dcm", 1, at(0.625 * 5 + 0.019));
  const std::string err = refusal(".");
  EXPECT_NE(err.find("non-uniform slice spacing: "), std::string::npos) << err;
  EXPECT_NE(err.find("s5.dcm"), std::string::npos) << err;
}

// A series of Enhanced MR files of one frame each (as some scanners write them): each file's
// position and pixel spacing are in its functional groups, and the series reads as a series of
// slices does; not "no ImagePositionPatient".
TEST_F(DicomFiles, EnhancedFilesOfOneFrameEachAreASeries) {
  REQUIRE_ITK();
  for (int k = 0; k < 4; ++k)
    write("e" + std::to_string(k) + ".dcm", {k}, {at(1.5 * k)}, {}, std::to_string(k + 1));
  expect_volume(".", {0, 1, 2, 3}, first_);
}

// An enhanced file whose frames have no positions: GDCM placed them 1 mm apart from 0, 0, 0.
// Row and column cosines that are not at right angles: a sheared frame. Both refused.
TEST_F(DicomFiles, FramesWithoutPositionsOrAtAnAngleAreRefused) {
  REQUIRE_ITK();
  write("nowhere.dcm", {0, 1, 2, 3}, {});
  EXPECT_NE(refusal("nowhere.dcm")
                .find("nowhere.dcm: its frames have no ImagePositionPatient "
                      "(PlanePositionSequence), so they cannot be placed"),
            std::string::npos);
  std::vector<Vec3d> up;
  for (int k = 0; k < 4; ++k) up.push_back(at(1.5 * k));
  write("sheared.dcm", {0, 1, 2, 3}, up,
        [&](std::size_t) { return testing::dicom::sequence(0x0020, 0x9116, {orientation(0.5)}); });
  EXPECT_NE(refusal("sheared.dcm")
                .find("sheared.dcm: ImageOrientationPatient (0020,0037) is not two unit vectors "
                      "at right angles"),
            std::string::npos);
}

// RT Dose places its frames by offsets along the normal (GridFrameOffsetVector): in any order
// they are read along it (GDCM refused offsets that descend, "spacing -1.5"), and a missing
// frame is named (GDCM read it with the first step, exit 0).
TEST_F(DicomFiles, DoseFramesArePlacedByTheirOffsets) {
  REQUIRE_ITK();
  write_dose("up.dcm", {0, 1, 2, 3}, {0, 1.5, 3, 4.5});
  expect_volume("up.dcm", {0, 1, 2, 3}, first_);
  write_dose("down.dcm", {3, 2, 1, 0}, {0, -1.5, -3, -4.5});
  expect_volume("down.dcm", {0, 1, 2, 3}, at(-4.5));
  write_dose("gap.dcm", {0, 1, 2, 3}, {0, 1.5, 4.5, 6});
  EXPECT_NE(refusal("gap.dcm").find("a gap of 3 mm between frames 2 and 3 where the frames lie "
                                    "1.5 mm apart (about 1 frame missing)"),
            std::string::npos);
}

// Frames without positions of their own, which GDCM stacks as slices whatever they are, 1 mm
// apart where it finds no distance between them: read where they are slices by the file's
// FrameIncrementPointer and GDCM reads their distance (NM tomography: SpacingBetweenSlices);
// otherwise refused naming what they run over (a cine loop's FrameTime, a gated study's time
// slots) or the missing distance, unless --spacing says how far apart they lie.
TEST_F(DicomFiles, FramesWithoutPositionsAreSlicesWhereTheFileSaysSo) {
  REQUIRE_ITK();
  using testing::dicom::element;
  const auto vector = [](const std::vector<int>& values) {
    std::string out;
    for (const int v : values) out += testing::dicom::u16(static_cast<std::uint16_t>(v));
    return out;
  };
  const std::string nm = "1.2.840.10008.5.1.4.1.1.20";
  // NM gives its position and orientation in DetectorInformationSequence, and GDCM reads them
  // there.
  const std::string between =
      element(0x0018, 0x0088, "DS", "1.5") +
      testing::dicom::sequence(0x0054, 0x0022, {position(first_) + orientation()});
  write_frames("nm.dcm", nm, "NM", {0, 1, 2, 3}, {{0x0054, 0x0010}, {0x0054, 0x0080}},
               between + element(0x0054, 0x0010, "US", vector({1, 1, 1, 1})) +
                   element(0x0054, 0x0080, "US", vector({1, 2, 3, 4})));
  expect_volume("nm.dcm", {0, 1, 2, 3}, first_);
  write_frames("gated.dcm", nm, "NM", {0, 1, 2, 3}, {{0x0054, 0x0070}, {0x0054, 0x0080}},
               between + element(0x0054, 0x0070, "US", vector({1, 1, 2, 2})) +
                   element(0x0054, 0x0080, "US", vector({1, 2, 1, 2})));
  EXPECT_NE(refusal("gated.dcm")
                .find("its 4 frames run over TimeSlotVector (0054,0070) (its "
                      "FrameIncrementPointer), not over slice positions"),
            std::string::npos);
  write_frames("apart.dcm", nm, "NM", {0, 1, 2, 3}, {{0x0054, 0x0080}},
               element(0x0054, 0x0080, "US", vector({1, 2, 3, 4})));
  EXPECT_NE(refusal("apart.dcm")
                .find("its 4 frames carry no positions and no "
                      "SpacingBetweenSlices (0018,0088), so the distance between "
                      "them is unknown"),
            std::string::npos);
  write_frames("cine.dcm", "1.2.840.10008.5.1.4.1.1.3.1", "US", {0, 1, 2, 3}, {{0x0018, 0x1063}},
               element(0x0018, 0x1063, "DS", "33.3"));
  EXPECT_NE(refusal("cine.dcm").find("its 4 frames run over FrameTime (0018,1063)"),
            std::string::npos);
  const CliResult r = run("extract cine.dcm -o out.ply --iso 500 -q --spacing 0.3,0.7,1.5");
  EXPECT_EQ(r.code, 0) << r.err;
  fs::remove(dir_ / "out.ply");
  write_frames("capture.dcm", "1.2.840.10008.5.1.4.1.1.7.3", "OT", {0, 1, 2, 3}, {},
               element(0x0018, 0x2010, "DS", "0.7\\0.3"));
  EXPECT_NE(refusal("capture.dcm")
                .find("GDCM reads no distance between the frames of Multi-frame Grayscale Word "
                      "Secondary Capture Image Storage files"),
            std::string::npos);
}

// Slices of their own slopes: each rescaled by its own, and info says so (it showed the first
// slice's slope as the series').
TEST_F(DicomFiles, SlicesOfTheirOwnSlopes) {
  REQUIRE_ITK();
  for (int k = 0; k < 4; ++k)
    write_slice("s" + std::to_string(k) + ".dcm", k, at(1.5 * k), true, 2 + k % 2);
  const Volume v = read_volume(dir_.string());
  ASSERT_EQ(v.dims(), (Index3{kColumns, kRows, 4}));
  for (int k = 0; k < 4; ++k)
    EXPECT_EQ(v.view().value(2, 3, k), (2 + k % 2) * sample(k, 3, 2)) << k;
  CliResult r = run("info .");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("rescale  per slice: value = stored x 2..3 + 0..0, each slice by its own"),
            std::string::npos)
      << r.out;
  r = run("info . --json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("\"per_slice\": true"), std::string::npos) << r.out;
}

// Several multi-frame files of one series (stacks, echoes): the folder is refused naming the
// first; each file named is read by itself. The message said "slice of 12x16x6 where a.dcm has
// 12x16x1", naming one file twice.
TEST_F(DicomFiles, SeveralMultiFrameFilesOfOneSeries) {
  REQUIRE_ITK();
  std::vector<Vec3d> up, further;
  for (int k = 0; k < 6; ++k) {
    up.push_back(at(1.5 * k));
    further.push_back(at(20 + 1.5 * k));
  }
  write("a.dcm", {0, 1, 2, 3, 4, 5}, up, {}, "1");
  write("b.dcm", {0, 1, 2, 3, 4, 5}, further, {}, "2");
  const CliResult r = run("info .");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find(": a multi-frame file in a series of several files ("), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("holds 6 frames); isotile reads such a file by itself: name it"),
            std::string::npos)
      << r.err;
  expect_volume("a.dcm", {0, 1, 2, 3, 4, 5}, first_);
  expect_volume("b.dcm", {0, 1, 2, 3, 4, 5}, at(20));
}

// --- bad input -------------------------------------------------------------------------------

class BadHeaders : public CliTest {
 protected:
  void expect_one_line(const std::string& file, const std::string& what) {
    const CliResult r = run("extract " + file + " -o out.ply --iso 0.5 -q");
    EXPECT_EQ(r.code, 1) << file;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << file << ": " << r.err;
    EXPECT_EQ(r.err.rfind("isotile: error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(what), std::string::npos) << file << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
  }
  std::string write(const std::string& name, const std::string& bytes) {
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
    return name;
  }
};

TEST_F(BadHeaders, NiftiAndMetaImage) {
  REQUIRE_ITK();
  const Volume raw = make_field_volume(*parse_field_spec("field:sphere:12"));
  write_itk((dir_ / "good.nii").string(), raw.bytes(), raw.type(), raw.dims(), {1, 1, 1}, {0, 0, 0},
            kIdentity3);
  write_itk((dir_ / "good.mha").string(), raw.bytes(), raw.type(), raw.dims(), {1, 1, 1}, {0, 0, 0},
            kIdentity3);
  const std::string nii = testing::slurp(dir_ / "good.nii");
  const std::string mha = testing::slurp(dir_ / "good.mha");
  expect_one_line(write("short.nii", nii.substr(0, 200)), "NIfTI header truncated");
  expect_one_line(write("cut.nii", nii.substr(0, nii.size() - 100)), "samples need");
  std::string big = nii;
  const std::int16_t huge = 30000;
  std::memcpy(big.data() + 42, &huge, 2);
  expect_one_line(write("big.nii", big), "samples need");
  std::string type = nii;
  const std::int16_t complex = 32;
  std::memcpy(type.data() + 70, &complex, 2);
  expect_one_line(write("type.nii", type), "datatype 32 is not supported");
  expect_one_line(write("junk.nii", std::string(400, 'x')), "not a NIfTI file");
  // A NIfTI-2 header (sizeof_hdr 540, magic "n+2"): ITK 5.2 cannot read it, and says so less.
  std::string v2(560, '\0');
  const std::int32_t size2 = 540;
  std::memcpy(v2.data(), &size2, 4);
  std::memcpy(v2.data() + 4, "n+2\0\r\n\032\n", 8);
  expect_one_line(write("v2.nii", v2), "a NIfTI-2 file, which ITK 5.2's NIfTI reader cannot read");
  expect_one_line(write("cut.mha", mha.substr(0, mha.size() - 10)), "samples need");
  std::string dims = mha;
  dims.replace(dims.find("DimSize = 12 12 12"), 18, "DimSize = 12 12 99");
  expect_one_line(write("dims.mha", dims), "samples need");
  expect_one_line(write("noend.mha", "ObjectType = Image\nNDims = 3\n"), "no ElementDataFile");
  std::string et = mha;
  et.replace(et.find("MET_FLOAT"), 9, "MET_LONG_LONG");
  expect_one_line(write("type.mha", et), "ElementType 'MET_LONG_LONG' is not supported");
  // Fewer values than axes: MetaIO failed with five lines naming DimSize.
  std::string spacing = mha;
  const std::size_t line_at = spacing.find("ElementSpacing = ");
  spacing.replace(line_at, spacing.find('\n', line_at) - line_at, "ElementSpacing = 2 3");
  expect_one_line(write("spacing.mha", spacing),
                  "MetaImage ElementSpacing has 2 values where NDims 3 needs 3");
  std::string offset = mha;
  const std::size_t offset_at = offset.find("Offset = ");
  offset.replace(offset_at, offset.find('\n', offset_at) - offset_at, "Offset = 7");
  expect_one_line(write("offset.mha", offset), "MetaImage Offset has 1 value where NDims 3");
  expect_one_line(write("junk.tif", std::string(64, 'x')), "not a TIFF file");
}

TEST_F(BadHeaders, Mrc) {
  const Volume raw = make_field_volume(*parse_field_spec("field:sphere:12"));
  write_mrc(dir_ / "good.mrc", raw, MrcSpec{});
  const std::string mrc = testing::slurp(dir_ / "good.mrc");
  expect_one_line(write("short.mrc", mrc.substr(0, 500)), "MRC header truncated");
  expect_one_line(write("cut.mrc", mrc.substr(0, mrc.size() - 4)), "the MRC header");
  std::string mode = mrc;
  mode[12] = 4;
  expect_one_line(write("mode.mrc", mode), "MRC mode 4 is not supported");
  std::string map = mrc;
  map[64] = 2;
  expect_one_line(write("map.mrc", map), "is not a permutation");
  std::string n = mrc;
  n[2] = 0x40;  // nx of 4 million
  expect_one_line(write("n.mrc", n), "the MRC header");
  std::string ext = mrc;
  ext[95] = static_cast<char>(0x80);  // NSYMBT negative
  expect_one_line(write("ext.mrc", ext), "NSYMBT");
  // Geometry MRC2014 has no "unknown" for: refused, never replaced (a NaN ORIGIN was read as 0,
  // a negative cell length as 1 per voxel, exit 0).
  const auto with_float = [&](std::size_t at, float f) {
    std::string m = mrc;
    std::memcpy(m.data() + at, &f, 4);
    return m;
  };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  expect_one_line(write("origin.mrc", with_float(200, nan)), "MRC ORIGIN along Y is nan");
  expect_one_line(write("cell.mrc", with_float(48, -12)), "MRC cell length along Z is -12");
  expect_one_line(write("cellnan.mrc", with_float(40, nan)), "MRC cell length along X is nan");
  expect_one_line(write("angle.mrc", with_float(56, 200)), "MRC cell angle beta is 200");
  expect_one_line(write("anglenan.mrc", with_float(60, nan)), "MRC cell angle gamma is nan");
  // Left unset (0): 1 per voxel and 90 degrees, as older writers leave them.
  std::string unset = with_float(44, 0);
  std::memset(unset.data() + 52, 0, 12);
  std::ofstream(dir_ / "unset.mrc", std::ios::binary) << unset;
  const VolumeHeader h = read_volume_header((dir_ / "unset.mrc").string());
  EXPECT_EQ(h.spacing, (Vec3d{1, 1, 3}));  // Y's cell length unset; X's and Z's kept
  EXPECT_FALSE(h.world.has_value());
}

// --- damaged and foreign inputs (issue 38) ---------------------------------------------------

// Copies of good files cut short or corrupted at run time: every one must be refused with one
// line naming the file, in core, out of core (--memory) and by `info`, and leave no output.
class DamagedInputs : public CliTest {
 protected:
  std::string write(const std::string& name, const std::string& bytes) {
    std::ofstream(dir_ / name, std::ios::binary) << bytes;
    return name;
  }
  static std::string gzip(const std::string& bytes) {
    std::string out(compressBound(static_cast<uLong>(bytes.size())) + 64, '\0');
    z_stream z{};
    deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);  // gzip wrapper
    z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
    z.avail_in = static_cast<uInt>(bytes.size());
    z.next_out = reinterpret_cast<Bytef*>(out.data());
    z.avail_out = static_cast<uInt>(out.size());
    EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
    out.resize(z.total_out);
    deflateEnd(&z);
    return out;
  }
  static std::string zlib(const std::string& bytes) {
    uLongf n = compressBound(static_cast<uLong>(bytes.size()));
    std::string out(n, '\0');
    EXPECT_EQ(compress2(reinterpret_cast<Bytef*>(out.data()), &n,
                        reinterpret_cast<const Bytef*>(bytes.data()),
                        static_cast<uLong>(bytes.size()), 6),
              Z_OK);
    out.resize(n);
    return out;
  }
  // extract in core, extract out of core and info: exit 1, one line naming `file` and holding
  // `what`, no output file.
  void expect_refused(const std::string& file, const std::string& what, bool out_of_core = true,
                      const std::string& named = "") {
    std::vector<std::string> commands = {"extract '" + file + "' -o out.ply --iso 0.5 -q",
                                         "info '" + file + "'"};
    if (out_of_core)
      commands.push_back("extract '" + file + "' -o out.ply --iso 0.5 -q --memory 1MiB");
    for (const std::string& c : commands) {
      const CliResult r = run(c);
      EXPECT_EQ(r.code, 1) << c << ": " << r.err;
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << c << ": " << r.err;
      EXPECT_NE(r.err.find(what), std::string::npos) << c << ": " << r.err;
      EXPECT_EQ(r.err.find("<fd:"), std::string::npos) << c << ": " << r.err;  // zlib's name
      EXPECT_NE(r.err.find(named.empty() ? fs::path(file).filename().string() : named),
                std::string::npos)
          << r.err;
      EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << c;
    }
  }
  std::uint64_t triangles(const std::string& file, const std::string& more = "",
                          const std::string& iso = "0.5") {
    const CliResult r =
        run("extract '" + file + "' -o ok.ply --iso " + iso + " -q --stats - " + more);
    EXPECT_EQ(r.code, 0) << file << ": " << r.err;
    const std::size_t at = r.out.find("\"triangles\":");
    return at == std::string::npos ? 0 : std::stoull(r.out.substr(at + 12));
  }
};

TEST_F(DamagedInputs, CompressedNiftiAndMetaImageMustInflateToEverySample) {
  REQUIRE_ITK();
  const Volume raw = make_field_volume(*parse_field_spec("field:sphere:40"));
  write_itk((dir_ / "good.nii.gz").string(), raw.bytes(), raw.type(), raw.dims(), {1, 1, 1},
            {0, 0, 0}, kIdentity3);
  write_itk((dir_ / "plain.mha").string(), raw.bytes(), raw.type(), raw.dims(), {1, 1, 1},
            {0, 0, 0}, kIdentity3);
  const std::uint64_t want = triangles("good.nii.gz");
  ASSERT_GT(want, 500u);
  // A compressed MetaImage: the plain one's header with its samples deflated as MetaIO does.
  const std::string plain = testing::slurp(dir_ / "plain.mha");
  const std::size_t data_at = plain.find("ElementDataFile = LOCAL\n") + 24;
  const std::string packed = zlib(plain.substr(data_at));
  std::string header = plain.substr(0, data_at);
  header.insert(header.find("ElementType"), "CompressedData = True\nCompressedDataSize = " +
                                                std::to_string(packed.size()) + "\n");
  write("good.mha", header + packed);
  EXPECT_EQ(triangles("good.mha"), want);
  // Names match in any case.
  fs::copy_file(dir_ / "good.mha", dir_ / "UPPER.MHA");
  fs::copy_file(dir_ / "good.nii.gz", dir_ / "UPPER.NII.GZ");
  EXPECT_EQ(triangles("UPPER.MHA"), want);
  EXPECT_EQ(triangles("UPPER.NII.GZ"), want);
  // ITK's nifti library refuses mixed case: said in one line that names the way out.
  fs::copy_file(dir_ / "good.nii.gz", dir_ / "mixed.nii.GZ");
  expect_refused("mixed.nii.GZ", "takes the extension in lower or upper case only");
  write_itk((dir_ / "detached.mhd").string(), raw.bytes(), raw.type(), raw.dims(), {1, 1, 1},
            {0, 0, 0}, kIdentity3);
  fs::copy_file(dir_ / "detached.mhd", dir_ / "DETACHED.MHD");
  EXPECT_EQ(triangles("DETACHED.MHD"), want);
  // A data file name with a space is one file to MetaIO (only `%` or LIST name several): it was
  // refused as "data in several files".
  std::string detached = testing::slurp(dir_ / "detached.mhd");
  const std::size_t name_at = detached.find("ElementDataFile = ") + 18;
  const std::string data_name = detached.substr(name_at, detached.find('\n', name_at) - name_at);
  fs::copy_file(dir_ / data_name, dir_ / "my data.raw");
  detached.replace(name_at, data_name.size(), "my data.raw");
  write("spaced.mhd", detached);
  EXPECT_EQ(triangles("spaced.mhd"), want);
  EXPECT_EQ(triangles("spaced.mhd", "--memory 1MiB"), want);

  const std::string nii = testing::slurp(dir_ / "good.nii.gz");
  expect_refused(write("cut.nii.gz", nii.substr(0, nii.size() * 2 / 3)),
                 "compressed data cut off: it inflates to");
  // Only the trailer cut: every sample is there, and the message says so.
  expect_refused(write("trailer.nii.gz", nii.substr(0, nii.size() - 4)),
                 "are there but the stream's end is cut off");
  std::string flipped = nii;
  flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x55);
  expect_refused(write("flipped.nii.gz", flipped), "corrupt compressed data");
  // Bytes after the gzip stream that do not start another member are left unread, as zlib and
  // gzip -d leave them, in core (checked here) as out of core (read by zlib); bytes that start
  // one must make a whole member.
  write("tail.nii.gz", nii + "trailing bytes, not gzip");
  EXPECT_EQ(triangles("tail.nii.gz"), want);
  EXPECT_EQ(triangles("tail.nii.gz", "--memory 1MiB"), want);
  expect_refused(write("member.nii.gz", nii + "\x1f\x8b\x08 not a member"), "corrupt");
  // A whole gzip stream that holds too few samples: the header of a bigger volume.
  const std::string nii_plain = [&] {
    gzFile f = gzopen((dir_ / "good.nii.gz").string().c_str(), "rb");
    std::string out(1 << 20, '\0');
    const int n = gzread(f, out.data(), static_cast<unsigned>(out.size()));
    gzclose(f);
    out.resize(static_cast<std::size_t>(std::max(n, 0)));
    return out;
  }();
  ASSERT_GT(nii_plain.size(), raw.byte_size());
  expect_refused(write("short.nii.gz", gzip(nii_plain.substr(0, nii_plain.size() - 4000))),
                 "expected (too short)");

  const std::string mha = testing::slurp(dir_ / "good.mha");
  expect_refused(write("cut.mha", mha.substr(0, mha.size() - packed.size() / 3)),
                 "(truncated file)");
  // MetaIO inflates CompressedDataSize bytes; without it, the header's own file from its first
  // byte (the header's text): "Uncompress failed" on stderr and samples never written.
  std::string unsized = mha;
  const std::size_t size_line = unsized.find("CompressedDataSize");
  unsized.erase(size_line, unsized.find('\n', size_line) + 1 - size_line);
  expect_refused(write("unsized.mha", unsized), "needs CompressedDataSize");
  std::string small = mha;
  small.replace(small.find(std::to_string(packed.size())), std::to_string(packed.size()).size(),
                std::to_string(packed.size() - 100));
  expect_refused(write("small.mha", small), "compressed data cut off");
  // MetaIO reads data in the header's file under any of its three spellings of LOCAL.
  std::string lower = mha;
  lower.replace(lower.find("ElementDataFile = LOCAL"), 23, "ElementDataFile = local");
  write("lower.mha", lower);
  EXPECT_EQ(triangles("lower.mha"), want);
  // Header says more samples than the stream holds.
  std::string dims = mha;
  dims.replace(dims.find("DimSize = 40 40 40"), 18, "DimSize = 40 40 41");
  expect_refused(write("dims.mha", dims), "(too short)");
  expect_refused(write("CUT.MHA", mha.substr(0, mha.size() - packed.size() / 3)),
                 "(truncated file)");
}

TEST_F(DamagedInputs, GzipRawInCoreAndOutOfCore) {
  const std::string gz =
      testing::slurp(fs::path(ISOTILE_TEST_DATA) / "nucleon_41x41x41_uint8.raw.gz");
  ASSERT_GT(gz.size(), 100u);
  write("good_41x41x41_uint8.raw.gz", gz);
  ASSERT_GT(triangles("good_41x41x41_uint8.raw.gz", "", "60"), 100u);
  expect_refused(write("half_41x41x41_uint8.raw.gz", gz.substr(0, gz.size() / 2)), "truncated");
  // Only the trailer (CRC and length) cut: every sample is there, the stream is not whole.
  expect_refused(write("trailer_41x41x41_uint8.raw.gz", gz.substr(0, gz.size() - 4)),
                 "all 68921 bytes are there but the stream's end (CRC and length) is cut off");
  std::string bad = gz;
  bad[bad.size() - 6] = static_cast<char>(bad[bad.size() - 6] ^ 0x1);  // the CRC
  expect_refused(write("crc_41x41x41_uint8.raw.gz", bad), "gzip");
}

TEST_F(DamagedInputs, NrrdRawAndGzipMustHoldEverySample) {
  const std::string gz =
      testing::slurp(fs::path(ISOTILE_TEST_DATA) / "nucleon_41x41x41_uint8.raw.gz");
  const std::string header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 41 41 41\n";
  write("good.nrrd", header + "encoding: gzip\n\n" + gz);
  ASSERT_GT(triangles("good.nrrd", "", "60"), 100u);
  // teem takes a cut-off gzip stream for the end of the data and leaves the rest as it was (in
  // core isotile checks the length); out of core the stream is read slab by slab, its end checked.
  expect_refused(write("cut.nrrd", header + "encoding: gzip\n\n" + gz.substr(0, gz.size() / 2)),
                 "data cut off");
  expect_refused(write("trailer.nrrd", header + "encoding: gzip\n\n" + gz.substr(0, gz.size() - 4)),
                 "cut off");
  // Detached gzip data, read slab by slab out of core.
  write("data.raw.gz", gz.substr(0, gz.size() - 4));
  expect_refused(write("detached.nhdr", header + "encoding: gzip\ndata file: data.raw.gz\n\n"),
                 "cut off", true, "data.raw.gz");
}

// What teem reads, isotile reads the same in core and out of core: attached raw data after a byte
// skip (counted once: teem has passed it when it hands the file over), gzip data of several
// members, or after skipped lines of text; raw data longer than the samples is refused in core
// as out of core (teem reads it with a warning).
TEST_F(DamagedInputs, NrrdSkipsAndMembersReadAsTeemReadsThem) {
  gzFile f = gzopen((fs::path(ISOTILE_TEST_DATA) / "nucleon_41x41x41_uint8.raw.gz").c_str(), "rb");
  std::string samples(41 * 41 * 41, '\0');
  ASSERT_EQ(gzread(f, samples.data(), static_cast<unsigned>(samples.size())),
            static_cast<int>(samples.size()));
  gzclose(f);
  const std::string header = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 41 41 41\n";
  write("plain.nrrd", header + "encoding: raw\n\n" + samples);
  const std::string want = run("extract plain.nrrd -o want.ply --iso 60 -q").err;
  ASSERT_TRUE(want.empty()) << want;
  const std::string reference = testing::slurp(dir_ / "want.ply");
  auto same_mesh = [&](const std::string& file) {
    for (const char* memory : {"", " --memory 1MiB"}) {
      const CliResult r = run("extract " + file + " -o got.ply --iso 60 -q" + memory);
      ASSERT_EQ(r.code, 0) << file << memory << ": " << r.err;
      EXPECT_EQ(testing::slurp(dir_ / "got.ply"), reference) << file << memory;
    }
  };
  write("skip.nrrd", header + "encoding: raw\nbyte skip: 5\n\n12345" + samples);
  same_mesh("skip.nrrd");
  write("lines.nrrd", header + "encoding: raw\nline skip: 2\n\nl1\nl2\n" + samples);
  same_mesh("lines.nrrd");
  const std::size_t half = samples.size() / 2;
  write("members.nrrd",
        header + "encoding: gzip\n\n" + gzip(samples.substr(0, half)) + gzip(samples.substr(half)));
  same_mesh("members.nrrd");
  // Bytes after the last member that do not start another are left unread (as zlib, gzip -d and
  // teem leave them); they were refused in core only.
  write("tail.nrrd", header + "encoding: gzip\n\n" + gzip(samples) + std::string(300, '\0'));
  same_mesh("tail.nrrd");
  write("text.nrrd", header + "encoding: gzip\n\n" + gzip(samples) + "trailing bytes");
  same_mesh("text.nrrd");
  expect_refused(write("member.nrrd", header + "encoding: gzip\n\n" + gzip(samples) +
                                          std::string("\x1f\x8b\x08", 3) + "not a member"),
                 "corrupt");
  write("lines.raw.gz", "a line of text\n" + gzip(samples));
  write("lines.nhdr", header + "encoding: gzip\ndata file: lines.raw.gz\nline skip: 1\n");
  same_mesh("lines.nhdr");
  expect_refused(write("long.nrrd", header + "encoding: raw\n\n" + samples + "1234567"),
                 "(too long)");
  expect_refused(
      write("long_skip.nrrd", header + "encoding: raw\nbyte skip: 5\n\n12345" + samples + "12"),
      "(too long)");
}

TEST_F(DamagedInputs, GzipMrcIsReadDirectlyAndMustBeWhole) {
  const Volume raw = make_field_volume(*parse_field_spec("field:sphere:24"));
  write_mrc(dir_ / "good.mrc", raw, MrcSpec{});
  const std::string mrc = testing::slurp(dir_ / "good.mrc");
  const std::uint64_t want = triangles("good.mrc");
  ASSERT_GT(want, 100u);
  write("emdb.map.gz", gzip(mrc));
  EXPECT_EQ(triangles("emdb.map.gz"), want);
  EXPECT_EQ(triangles("emdb.map.gz", "--memory 1MiB"), want);
  write("UPPER.MRC.GZ", gzip(mrc));
  EXPECT_EQ(triangles("UPPER.MRC.GZ"), want);
  const std::string gz = gzip(mrc);
  expect_refused(write("cut.map.gz", gz.substr(0, gz.size() / 2)), "gzip data cut off");
  expect_refused(write("trailer.map.gz", gz.substr(0, gz.size() - 4)),
                 "are there but the stream's end (CRC and length) is cut off");
  expect_refused(write("short.ccp4.gz", gzip(mrc.substr(0, mrc.size() - 100))), "(too short)");
  expect_refused(write("long.map.gz", gzip(mrc + "xxxx")), "(too long)");
  // A wrong CRC: zlib's words, without the path it puts first (the message names the file).
  std::string crc = gzip(mrc);
  crc[crc.size() - 8] = static_cast<char>(crc[crc.size() - 8] ^ 1);
  expect_refused(write("crc.map.gz", crc), "crc.map.gz: corrupt gzip data (incorrect data check)");
}

TEST_F(DamagedInputs, ForeignFormatsAreNamedByTheirContent) {
  const std::string bucky = "bucky_32x32x32_uint8.raw";
  expect_refused(write("map.map.bz2", std::string("BZh91AY&SY") + std::string(40, '\0')),
                 "bzip2-compressed data, which isotile does not read; decompress it first (bunzip2",
                 false);
  // The name says raw, the content says otherwise: content wins.
  expect_refused(write(bucky, std::string("\xfd"
                                          "7zXZ",
                                          5) +
                                  std::string(40, '\0')),
                 "xz-compressed data", false);
  expect_refused(write("v.nii", std::string("\x28\xb5\x2f\xfd", 4) + std::string(40, '\0')),
                 "zstd-compressed data", false);
  expect_refused(write("v.h5", std::string("\x89HDF\r\n\x1a\n", 8) + std::string(40, '\0')),
                 "an HDF5 file", false);
  expect_refused(write("v.vtk", "# vtk DataFile Version 3.0\nimage\nBINARY\n"), "a legacy VTK file",
                 false);
  // A NIfTI or Analyze header beside its .img (it got the raw name's message: pass --dims).
  std::string hdr(348, '\0');
  hdr[0] = '\x5c';
  hdr[1] = '\x01';
  expect_refused(write("a.hdr", hdr), "an Analyze 7.5 header (.hdr, samples in a separate .img",
                 false);
  hdr.replace(344, 4, std::string("ni1\0", 4));
  expect_refused(write("n.HDR", hdr),
                 "a NIfTI header whose samples are in a separate .img file, which isotile does not "
                 "read; convert the pair to a single .nii",
                 false);
  expect_refused(write("v.vti", "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\">\n"),
                 "a VTK XML file", false);
  fs::create_directories(dir_ / "v.zarr");
  write("v.zarr/.zarray", "{}");
  expect_refused("v.zarr", "a Zarr store", false);
  // A mesh where a volume belongs: by its extension, or a PLY or OFF header under any name
  // (it was taken for raw samples whose dims and type the name did not give).
  expect_refused(write("m.stl", std::string(84, '\0')), "a mesh, not a volume", false);
  expect_refused(write("m.obj", "v 0 0 0\n"), "a mesh, not a volume", false);
  expect_refused(write("mesh_4x4x4_uint8.raw", "ply\nformat ascii 1.0\n" + std::string(60, ' ')),
                 "a mesh, not a volume: extraction reads samples on a grid", false);
  expect_refused(write("m.dat", "OFF\n3 1 0\n"), "a mesh, not a volume", false);
}

TEST_F(DamagedInputs, DicomSliceCutShort) {
  REQUIRE_ITK();
  const fs::path series = testing::shared_volume("dicom_uih_t1_head_slab");
  ISOTILE_REQUIRE_SHARED(series);
  fs::create_directories(dir_ / "s");
  for (int n = 60; n < 66; ++n) {
    char name[32];
    std::snprintf(name, sizeof name, "%08d.dcm", n);
    std::string bytes = testing::slurp(series / name);
    if (n == 62) bytes.resize(bytes.size() - 50000);  // rows of pixels lost
    if (n == 64) bytes.resize(5000);                  // the header cut
    write("s/" + std::string(name), bytes);
  }
  const CliResult r = run("extract s -o out.ply --iso 60 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("truncated file"), std::string::npos) << r.err;
  expect_refused("s/00000062.dcm", "needs 471040 bytes");  // any file of the series
  fs::remove(dir_ / "s" / "00000062.dcm");
  expect_refused("s", "00000064.dcm: DICOM");
  write("s/00000064.dcm", testing::slurp(series / "00000064.dcm"));
  // 62 missing: the 2 mm step is named by its two files, against the typical 1 mm.
  expect_refused(
      "s",
      "a gap of 2 mm between slices 00000063.dcm and 00000061.dcm where the slices lie 1 mm apart");
  // The slice as a bare explicit-VR data set (no preamble, no meta group), which GDCM reads as a
  // slice of the series: whole, the series reads; cut short, it is refused (it was read with
  // zeros for the lost rows).
  const std::string part10 = testing::slurp(series / "00000062.dcm");
  ASSERT_EQ(part10.substr(128, 4), "DICM");
  std::uint32_t meta = 0;
  std::memcpy(&meta, part10.data() + 140, 4);  // (0002,0000), the meta group's length
  const std::string bare = part10.substr(144 + meta);
  write("s/00000062.dcm", bare);
  const CliResult whole = run("info s");
  EXPECT_EQ(whole.code, 0) << whole.err;
  write("s/00000062.dcm", bare.substr(0, bare.size() - 100));
  expect_refused("s",
                 "00000062.dcm: not a DICOM file (no DICM marker, and not a readable "
                 "explicit-VR data set: DICOM pixel data (7FE0,0010) needs");
}

TEST_F(DamagedInputs, TiffCutShort) {
  REQUIRE_ITK();
  const fs::path tif = testing::shared_volume("tiff_arabidopsis_embryo/arabidopsis-embryo.tif");
  ISOTILE_REQUIRE_SHARED(tif);
  const std::string bytes = testing::slurp(tif);
  write("UPPER.TIF", bytes);
  const CliResult ok = run("info UPPER.TIF");
  EXPECT_EQ(ok.code, 0) << ok.err;
  expect_refused(write("cut.tif", bytes.substr(0, bytes.size() / 2)), "(truncated file)");
  // A stack of single pages with one cut: the directory of slices is refused.
  fs::create_directories(dir_ / "pages");
  const Volume v = field_as("field:sphere:16", ScalarType::UInt16);
  const std::size_t plane = 16 * 16 * sizeof(std::uint16_t);
  for (int k = 0; k < 16; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "s_%03d.tif", k);
    write_itk((dir_ / "pages" / name).string(), v.bytes() + k * plane, ScalarType::UInt16,
              {16, 16, 1}, {1, 1, 1}, {0, 0, 0}, kIdentity3);
  }
  ASSERT_EQ(run("info pages").code, 0);
  const std::string page = testing::slurp(dir_ / "pages" / "s_007.tif");
  write("pages/s_007.tif", page.substr(0, page.size() - 300));
  expect_refused("pages", "s_007.tif: TIFF page 1");
}

}  // namespace
}  // namespace isotile
