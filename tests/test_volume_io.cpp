// Volume readers: raw (plain and gzip), NRRD, OpenVDB, the dispatcher and the shared checks.
#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <teem/nrrd.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/errors.h"
#include "core/volume/finite_range.h"
#include "core/volume/volume_io.h"
#include "test_support.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

// Each test writes under a directory of its own, removed afterwards, so tests can run in parallel
// (ctest -j) without seeing each other's files.
class VolumeIo : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string(info->test_suite_name()) + "_" + info->name();
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = fs::temp_directory_path() /
           ("isotile_test_volume_io_" + std::to_string(::getpid()) + "_" + name);
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

void write_file(const std::string& path, const void* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary);
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  ASSERT_TRUE(out.good()) << path;
}

void write_file(const std::string& path, const std::string& text) {
  write_file(path, text.data(), text.size());
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_gzip(const std::string& path, const void* data, std::size_t size, int level = 6) {
  gzFile f = gzopen(path.c_str(), ("wb" + std::to_string(level)).c_str());
  ASSERT_NE(f, nullptr) << path;
  const auto* p = static_cast<const char*>(data);
  while (size > 0) {
    const unsigned n = static_cast<unsigned>(std::min<std::size_t>(size, 1u << 30));
    ASSERT_EQ(gzwrite(f, p, n), static_cast<int>(n));
    p += n;
    size -= n;
  }
  ASSERT_EQ(gzclose(f), Z_OK);
}

// Decompresses with zlib's inflate directly, not through gzread as the reader does, so the two
// paths check each other.
std::string inflate_gzip(const std::string& compressed) {
  z_stream s{};
  EXPECT_EQ(inflateInit2(&s, 16 + MAX_WBITS), Z_OK);
  s.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(compressed.data()));
  s.avail_in = static_cast<uInt>(compressed.size());
  std::string out;
  char buf[1 << 16];
  int ret = Z_OK;
  while (ret == Z_OK) {
    s.next_out = reinterpret_cast<Bytef*>(buf);
    s.avail_out = sizeof buf;
    ret = inflate(&s, Z_NO_FLUSH);
    out.append(buf, sizeof buf - s.avail_out);
  }
  EXPECT_EQ(ret, Z_STREAM_END);
  inflateEnd(&s);
  return out;
}

template <class E>
std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
    return {};
  }
  ADD_FAILURE() << "no exception";
  return {};
}

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

// Bytes of `values` stored with the given byte order, whatever this machine's order is.
template <class T>
std::vector<unsigned char> encode(const std::vector<T>& values, Endian endian) {
  std::vector<unsigned char> out(values.size() * sizeof(T));
  std::memcpy(out.data(), values.data(), out.size());
  const bool native_big = std::endian::native == std::endian::big;
  if ((endian == Endian::Big) != native_big)
    for (std::size_t i = 0; i < values.size(); ++i)
      std::reverse(out.begin() + i * sizeof(T), out.begin() + (i + 1) * sizeof(T));
  return out;
}

// Distinct values that reach both ends of T's range, so a wrong type, width or byte order shows.
template <class T>
std::vector<T> sample_values(std::size_t n) {
  std::vector<T> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    if constexpr (std::is_floating_point_v<T>)
      v[i] = static_cast<T>(static_cast<double>(i) * 0.75 - 3.125);
    else if constexpr (std::is_signed_v<T>)
      v[i] = static_cast<T>(static_cast<int>(i) * 3 - 7);
    else
      v[i] = static_cast<T>(i * 5 + 1);
  }
  v.front() = std::numeric_limits<T>::lowest();
  v.back() = std::numeric_limits<T>::max();
  if constexpr (std::is_same_v<T, double>) {  // the largest a float64 sample may be
    v.front() = -kLargestFloat64Sample;
    v.back() = kLargestFloat64Sample;
  }
  return v;
}

// ---------------------------------------------------------------------------------------------
// Raw file names

TEST(RawName, ParsesDimsAndType) {
  auto info = parse_raw_name("bonsai_256x256x256_uint8.raw.gz");
  ASSERT_TRUE(info);
  EXPECT_EQ(info->dims, (Index3{256, 256, 256}));
  EXPECT_EQ(info->type, ScalarType::UInt8);

  info = parse_raw_name("some/dir/my_scan_2x3x41_float32.raw");
  ASSERT_TRUE(info);
  EXPECT_EQ(info->dims, (Index3{2, 3, 41}));
  EXPECT_EQ(info->type, ScalarType::Float32);

  info = parse_raw_name("walnut_128x96x114_ushort.raw");  // aliases are accepted
  ASSERT_TRUE(info);
  EXPECT_EQ(info->dims, (Index3{128, 96, 114}));
  EXPECT_EQ(info->type, ScalarType::UInt16);

  info = parse_raw_name("x_1x1x1_float64.raw");
  ASSERT_TRUE(info);
  EXPECT_EQ(info->type, ScalarType::Float64);

  info = parse_raw_name("SCAN_64X32X16_UINT16.RAW.GZ");  // in any case, as other extensions
  ASSERT_TRUE(info);
  EXPECT_EQ(info->dims, (Index3{64, 32, 16}));
  EXPECT_EQ(info->type, ScalarType::UInt16);
}

TEST(RawName, RejectsOtherNames) {
  for (const char* name : {
           "bonsai.raw",                                 // no dims
           "bonsai_256x256_uint8.raw",                   // two dims
           "bonsai_256x256x256_complex.raw",             // unknown type
           "bonsai_256x256x256_uint8.nrrd",              // not raw
           "bonsai_256x256x256_uint8.raw.bz2",           // not gzip
           "bonsai_256x256x256_uint8",                   // no extension
           "_256x256x256_uint8.raw",                     // no NAME
           "bonsai_-2x256x256_uint8.raw",                // negative
           "bonsai_2.5x256x256_uint8.raw",               // not an integer
           "bonsai_99999999999999999999x1x1_uint8.raw",  // beyond 64 bits
           "bonsai_2x2x2_uint8.raw/other.raw",           // only the file name counts
       })
    EXPECT_FALSE(parse_raw_name(name)) << name;
}

// ---------------------------------------------------------------------------------------------
// Raw: every scalar type, both byte orders

template <class T>
class RawTyped : public VolumeIo {};
using AllTypes = ::testing::Types<std::int8_t, std::uint8_t, std::int16_t, std::uint16_t,
                                  std::int32_t, std::uint32_t, float, double>;
TYPED_TEST_SUITE(RawTyped, AllTypes);

TYPED_TEST(RawTyped, LittleEndianFromName) {
  using T = TypeParam;
  const ScalarType type = scalar_type_of<T>();
  const std::vector<T> values = sample_values<T>(3 * 2 * 4);
  const auto bytes = encode(values, Endian::Little);
  const std::string file = this->path("vol_3x2x4_" + std::string(scalar_name(type)) + ".raw");
  write_file(file, bytes.data(), bytes.size());

  const Volume v = read_raw(file, {});
  EXPECT_EQ(v.type(), type);
  EXPECT_EQ(v.dims(), (Index3{3, 2, 4}));
  EXPECT_EQ(v.spacing(), (Vec3d{1, 1, 1}));
  EXPECT_EQ(v.origin(), (Vec3d{0, 0, 0}));
  ASSERT_EQ(v.byte_size(), bytes.size());
  for (std::size_t n = 0; n < values.size(); ++n) EXPECT_EQ(v.data<T>()[n], values[n]) << n;
  // x varies fastest: sample (i, j, k) is element i + 3*(j + 2*k).
  EXPECT_EQ(v.view().value(2, 1, 3), static_cast<double>(values[2 + 3 * (1 + 2 * 3)]));
  EXPECT_EQ(v.view().value(1, 0, 2), static_cast<double>(values[1 + 3 * (0 + 2 * 2)]));
}

TYPED_TEST(RawTyped, BigEndianFromOptions) {
  using T = TypeParam;
  const ScalarType type = scalar_type_of<T>();
  const std::vector<T> values = sample_values<T>(2 * 3 * 2);
  const auto bytes = encode(values, Endian::Big);
  const std::string file = this->path("samples.be");
  write_file(file, bytes.data(), bytes.size());

  RawOptions options;
  options.dims = Index3{2, 3, 2};
  options.type = type;
  options.endian = Endian::Big;
  options.spacing = Vec3d{0.5, 0.25, 2};
  options.origin = Vec3d{-1, 2, 3.5};
  const Volume v = read_raw(file, options);
  EXPECT_EQ(v.type(), type);
  EXPECT_EQ(v.dims(), (Index3{2, 3, 2}));
  EXPECT_EQ(v.spacing(), (Vec3d{0.5, 0.25, 2}));
  EXPECT_EQ(v.origin(), (Vec3d{-1, 2, 3.5}));
  for (std::size_t n = 0; n < values.size(); ++n) EXPECT_EQ(v.data<T>()[n], values[n]) << n;
}

TYPED_TEST(RawTyped, GzipBothEndians) {
  using T = TypeParam;
  const ScalarType type = scalar_type_of<T>();
  const std::vector<T> values = sample_values<T>(5 * 4 * 3);
  for (Endian endian : {Endian::Little, Endian::Big}) {
    const auto bytes = encode(values, endian);
    const std::string file = this->path("g_5x4x3_" + std::string(scalar_name(type)) +
                                        (endian == Endian::Big ? "_be" : "_le") + ".raw.gz");
    // The suffix after the type breaks the name pattern; dims and type come from the options.
    RawOptions options;
    options.dims = Index3{5, 4, 3};
    options.type = type;
    options.endian = endian;
    write_gzip(file, bytes.data(), bytes.size());
    const Volume v = read_raw(file, options);
    EXPECT_EQ(v.dims(), (Index3{5, 4, 3}));
    for (std::size_t n = 0; n < values.size(); ++n) EXPECT_EQ(v.data<T>()[n], values[n]) << n;
  }
}

// ---------------------------------------------------------------------------------------------
// Raw: options, sizes and failures

TEST_F(VolumeIo, RawOptionsOverrideTheName) {
  const std::vector<std::uint8_t> values = {0, 1, 2, 3, 4, 5, 6, 255};
  const std::string file = path("v_2x2x2_uint8.raw");
  write_file(file, values.data(), values.size());

  RawOptions options;
  options.dims = Index3{8, 1, 1};
  Volume v = read_raw(file, options);
  EXPECT_EQ(v.dims(), (Index3{8, 1, 1}));
  EXPECT_EQ(v.type(), ScalarType::UInt8);

  options = {};
  options.type = ScalarType::Int8;
  v = read_raw(file, options);
  EXPECT_EQ(v.dims(), (Index3{2, 2, 2}));
  EXPECT_EQ(v.type(), ScalarType::Int8);
  EXPECT_EQ(v.data<std::int8_t>()[7], -1);
}

TEST_F(VolumeIo, RawWithoutDimsOrTypeSaysWhatToPass) {
  const std::string file = path("plain.raw");
  write_file(file, std::string(8, '\0'));
  std::string msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, file)) << msg;
  EXPECT_TRUE(contains(msg, "--dims X,Y,Z")) << msg;
  EXPECT_TRUE(contains(msg, "--type T")) << msg;

  RawOptions only_dims;
  only_dims.dims = Index3{2, 2, 2};
  msg = message_of<InputError>([&] { read_raw(file, only_dims); });
  EXPECT_TRUE(contains(msg, "the sample type is unknown")) << msg;
  EXPECT_TRUE(contains(msg, "pass --type T")) << msg;
  EXPECT_FALSE(contains(msg, "--dims")) << msg;  // given: not asked for again

  RawOptions only_type;
  only_type.type = ScalarType::UInt8;
  msg = message_of<InputError>([&] { read_raw(file, only_type); });
  EXPECT_TRUE(contains(msg, "the dims are unknown")) << msg;
  EXPECT_TRUE(contains(msg, "pass --dims X,Y,Z")) << msg;
  EXPECT_FALSE(contains(msg, "--type")) << msg;
}

TEST_F(VolumeIo, RawTooShortAndTooLong) {
  const std::string file = path("v_4x4x4_uint16.raw");
  write_file(file, std::string(100, 'a'));
  EXPECT_EQ(message_of<InputError>([&] { read_raw(file, {}); }),
            file + ": file holds 100 bytes but 4x4x4 uint16 needs 128 (too short)");
  write_file(file, std::string(129, 'a'));
  EXPECT_EQ(message_of<InputError>([&] { read_raw(file, {}); }),
            file + ": file holds 129 bytes but 4x4x4 uint16 needs 128 (too long)");
  write_file(file, std::string(128, 'a'));
  EXPECT_EQ(read_raw(file, {}).data<std::uint16_t>()[63], 0x6161);
}

// A file of several read slices (16 MiB each) and a partial last one, read by all threads: every
// byte lands where it belongs, in both byte orders.
TEST_F(VolumeIo, RawLargerThanOneSlice) {
  const Index3 dims{1024, 1024, 9};  // 9 Mi uint16 samples, 18 MiB
  std::string bytes(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]) * 2, '\0');
  for (std::size_t i = 0; i < bytes.size() / 2; ++i) {
    const auto v = static_cast<std::uint16_t>(i * 2654435761u >> 7);
    bytes[2 * i] = static_cast<char>(v & 0xff);
    bytes[2 * i + 1] = static_cast<char>(v >> 8);
  }
  const std::string file = path("big_1024x1024x9_uint16.raw");
  write_file(file, bytes);
  const Volume little = read_raw(file, {});
  RawOptions big_endian;
  big_endian.endian = Endian::Big;
  const Volume big = read_raw(file, big_endian);
  ASSERT_EQ(little.byte_size(), bytes.size());
  EXPECT_EQ(std::memcmp(little.bytes(), bytes.data(), bytes.size()), 0);
  std::size_t wrong = 0;
  for (std::size_t i = 0; i < bytes.size() / 2; ++i) {
    const auto v = static_cast<std::uint16_t>(i * 2654435761u >> 7);
    wrong += big.data<std::uint16_t>()[i] != __builtin_bswap16(v);
  }
  EXPECT_EQ(wrong, 0u);
}

TEST_F(VolumeIo, RawZeroAndNegativeDims) {
  const std::string file = path("v_0x4x4_uint8.raw");
  write_file(file, std::string());
  std::string msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, "positive")) << msg;

  RawOptions options;
  options.dims = Index3{2, -1, 2};
  msg = message_of<InputError>([&] { read_raw(file, options); });
  EXPECT_TRUE(contains(msg, "2x-1x2")) << msg;
}

TEST_F(VolumeIo, RawOverflowingDims) {
  const std::string file = path("v_4000000000x4000000000x4000000000_uint8.raw");
  write_file(file, std::string(8, 'a'));
  const std::string msg = message_of<CapacityError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, "overflow")) << msg;

  const std::string huge = path("v_99999999999999999999x1x1_uint8.raw");
  write_file(huge, std::string(8, 'a'));
  EXPECT_TRUE(contains(message_of<InputError>([&] { read_raw(huge, {}); }), "too large"));
}

TEST_F(VolumeIo, RawUnknownTypeName) {
  const std::string file = path("v_2x2x2_complex.raw");
  write_file(file, std::string(8, 'a'));
  const std::string msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, "unknown sample type 'complex'")) << msg;
  EXPECT_TRUE(contains(msg, "--type")) << msg;
}

TEST_F(VolumeIo, RawMissingFileAndDirectory) {
  const std::string file = path("missing_2x2x2_uint8.raw");
  EXPECT_EQ(message_of<IoError>([&] { read_raw(file, {}); }),
            "cannot open " + file + ": No such file or directory");
  const std::string gz = path("missing_2x2x2_uint8.raw.gz");
  EXPECT_EQ(message_of<IoError>([&] { read_raw(gz, {}); }),
            "cannot open " + gz + ": No such file or directory");
  // Reported as missing, not as lacking dims, when the name does not say them either.
  const std::string unnamed = path("scan.raw");
  EXPECT_EQ(message_of<IoError>([&] { read_raw(unnamed, {}); }),
            "cannot open " + unnamed + ": No such file or directory");
  const std::string dir = path("dir_2x2x2_uint8.raw");
  fs::create_directory(dir);
  EXPECT_TRUE(contains(message_of<IoError>([&] { read_raw(dir, {}); }), "Is a directory"));
}

// ---------------------------------------------------------------------------------------------
// Raw: gzip failures

std::vector<std::uint16_t> gzip_test_values(std::size_t n) {
  // Neither constant (which compresses to almost nothing) nor random (which deflate stores).
  std::vector<std::uint16_t> v(n);
  std::uint32_t state = 12345;
  for (std::size_t i = 0; i < n; ++i) {
    state = state * 1103515245u + 12345u;
    v[i] = static_cast<std::uint16_t>((i % 97) * 13 + ((state >> 16) & 7));
  }
  return v;
}

TEST_F(VolumeIo, GzipDecompressesWrongSize) {
  const std::vector<std::uint8_t> bytes(100, 7);
  const std::string longer = path("v_4x4x4_uint8.raw.gz");
  write_gzip(longer, bytes.data(), bytes.size());
  EXPECT_EQ(message_of<InputError>([&] { read_raw(longer, {}); }),
            longer + ": decompresses to more than the 64 bytes 4x4x4 uint8 needs (too long)");
  const std::string shorter = path("v_5x5x5_uint8.raw.gz");
  write_gzip(shorter, bytes.data(), bytes.size());
  EXPECT_EQ(message_of<InputError>([&] { read_raw(shorter, {}); }),
            shorter + ": decompresses to 100 bytes but 5x5x5 uint8 needs 125 (too short)");
}

TEST_F(VolumeIo, GzipCorrupt) {
  const auto values = gzip_test_values(32 * 32 * 32);
  const std::string file = path("c_32x32x32_uint16.raw.gz");
  write_gzip(file, values.data(), values.size() * 2);
  std::string gz = read_file(file);
  ASSERT_GT(gz.size(), 1000u);
  for (std::size_t i = gz.size() / 2; i < gz.size() / 2 + 16; ++i)
    gz[i] = static_cast<char>(~gz[i]);
  write_file(file, gz);
  const std::string msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_EQ(msg.rfind(file + ": ", 0), 0u) << msg;
  EXPECT_TRUE(contains(msg, "corrupt gzip data") || contains(msg, "decompresses to")) << msg;
}

TEST_F(VolumeIo, GzipCorruptChecksum) {
  // The payload still inflates, so only the CRC in the trailer shows the damage.
  const auto values = gzip_test_values(16 * 16 * 16);
  const std::string file = path("c_16x16x16_uint16.raw.gz");
  write_gzip(file, values.data(), values.size() * 2);
  std::string gz = read_file(file);
  gz[gz.size() - 8] = static_cast<char>(~gz[gz.size() - 8]);
  write_file(file, gz);
  EXPECT_EQ(message_of<InputError>([&] { read_raw(file, {}); }),
            file + ": corrupt gzip data: incorrect data check");
}

TEST_F(VolumeIo, GzipTruncated) {
  const auto values = gzip_test_values(32 * 32 * 32);
  const std::string file = path("t_32x32x32_uint16.raw.gz");
  write_gzip(file, values.data(), values.size() * 2);
  const std::string gz = read_file(file);

  write_file(file, gz.substr(0, gz.size() / 2));
  std::string msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, file + ": truncated gzip data")) << msg;

  // All samples inflate but the trailer is missing: caught by reading past the end.
  write_file(file, gz.substr(0, gz.size() - 4));
  msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, file + ": truncated gzip data")) << msg;
}

// Whole files are decompressed with libdeflate member by member; anything it does not take
// exactly (here: bytes after the last member, which zlib ignores) goes to zlib's stream, so both
// give the same volume.
TEST_F(VolumeIo, GzipMembersAndTrailingBytesReadAsZlibReadsThem) {
  const auto values = gzip_test_values(24 * 24 * 24);
  const std::size_t half = values.size() / 2 * 2;  // bytes
  const std::string a = path("a.gz"), b = path("b.gz");
  write_gzip(a, values.data(), half);
  write_gzip(b, reinterpret_cast<const char*>(values.data()) + half, values.size() * 2 - half);
  const std::string members = read_file(a) + read_file(b);
  const std::string expected(reinterpret_cast<const char*>(values.data()), values.size() * 2);
  ASSERT_EQ(inflate_gzip(read_file(a)) + inflate_gzip(read_file(b)), expected);
  for (const std::string& tail : {std::string(), std::string("trailing bytes, not gzip")}) {
    const std::string file = path("m_24x24x24_uint16.raw.gz");
    write_file(file, members + tail);
    const Volume v = read_raw(file, {});
    ASSERT_EQ(v.byte_size(), expected.size());
    EXPECT_EQ(std::memcmp(v.bytes(), expected.data(), expected.size()), 0) << tail;
  }
}

TEST_F(VolumeIo, GzipNameOnPlainDataIsRejected) {
  // zlib reads non-gzip data through unchanged; a .gz name on such a file is reported as such.
  const std::vector<std::uint8_t> bytes(4 * 4 * 4, 7);
  const std::string file = path("p_4x4x4_uint8.raw.gz");
  write_file(file, bytes.data(), bytes.size());
  const std::string msg = message_of<InputError>([&] { read_raw(file, {}); });
  EXPECT_TRUE(contains(msg, file + ": not gzip data")) << msg;
}

TEST_F(VolumeIo, LargeFilesCrossReadChunks) {
  // More than one 64 MiB read chunk, ending part-way into the second.
  const Index3 dims{1025, 256, 256};
  const std::size_t n = 1025u * 256u * 256u;
  std::vector<std::uint8_t> bytes(n);
  for (std::size_t i = 0; i < n; ++i) bytes[i] = static_cast<std::uint8_t>((i * 31) % 251);
  const std::string plain = path("big_1025x256x256_uint8.raw");
  write_file(plain, bytes.data(), n);
  const std::string gz = path("big_1025x256x256_uint8.raw.gz");
  write_gzip(gz, bytes.data(), n, 1);
  for (const std::string& file : {plain, gz}) {
    const Volume v = read_raw(file, {});
    EXPECT_EQ(v.dims(), dims);
    ASSERT_EQ(v.byte_size(), n);
    EXPECT_EQ(std::memcmp(v.bytes(), bytes.data(), n), 0) << file;
  }
}

// ---------------------------------------------------------------------------------------------
// NaN / Inf

TEST_F(VolumeIo, NonFiniteSamplesAreReported) {
  std::vector<float> values(4 * 3 * 5, 1.5f);
  auto at = [](int i, int j, int k) { return i + 4 * (j + 3 * k); };
  values[at(1, 2, 3)] = std::numeric_limits<float>::quiet_NaN();
  values[at(0, 0, 4)] = std::numeric_limits<float>::infinity();
  values[at(3, 2, 4)] = -std::numeric_limits<float>::infinity();
  const std::string file = path("nan_4x3x5_float32.raw");
  write_file(file, values.data(), values.size() * sizeof(float));
  EXPECT_EQ(message_of<InputError>([&] { read_raw(file, {}); }),
            file +
                ": 3 samples are NaN or Inf (first at x=1, y=2, z=3); isosurfaces need finite "
                "values");

  values.assign(values.size(), 0.0f);
  values[at(2, 1, 0)] = std::numeric_limits<float>::quiet_NaN();
  write_file(file, values.data(), values.size() * sizeof(float));
  EXPECT_EQ(message_of<InputError>([&] { read_raw(file, {}); }),
            file +
                ": 1 sample is NaN or Inf (first at x=2, y=1, z=0); isosurfaces need finite "
                "values");
}

TEST(CheckFinite, DoublesSubviewsAndIntegers) {
  std::vector<double> values(6 * 6 * 6, 0.0);
  values[4 + 6 * (5 + 6 * 2)] = std::nan("");
  const VolumeView view = dense_view(values.data(), ScalarType::Float64, {6, 6, 6});
  EXPECT_TRUE(contains(message_of<InputError>([&] { check_finite(view, "d"); }),
                       "d: 1 sample is NaN or Inf (first at x=4, y=5, z=2)"));
  // A brick reports global positions.
  const VolumeView brick = subview(view, {{3, 3, 1}, {6, 6, 4}});
  EXPECT_TRUE(contains(message_of<InputError>([&] { check_finite(brick, "b"); }),
                       "(first at x=4, y=5, z=2)"));
  EXPECT_NO_THROW(check_finite(subview(view, {{0, 0, 0}, {4, 6, 6}}), "clean"));

  const std::vector<std::int32_t> ints(8, -5);
  EXPECT_NO_THROW(check_finite(dense_view(ints.data(), ScalarType::Int32, {2, 2, 2}), "i"));
}

// Float64 samples past 1e100 are refused as NaN is: at 9e307 the difference of two samples was
// infinite (vertices snapped onto samples, NaN normals written to the file, exit 0).
TEST(CheckFinite, Float64SamplesPastTheLargestAreRefused) {
  std::vector<double> values(5 * 4 * 3, -kLargestFloat64Sample);
  values[7] = kLargestFloat64Sample;
  const VolumeView view = dense_view(values.data(), ScalarType::Float64, {5, 4, 3});
  EXPECT_NO_THROW(check_finite(view, "d"));
  EXPECT_NO_THROW(finite_value_range(view, "d"));
  values[2 + 5 * (3 + 4 * 1)] = -9e307;
  values[4 + 5 * (3 + 4 * 2)] = std::nextafter(kLargestFloat64Sample, 1e300);
  const std::string want =
      "d: 2 samples are past +-1e100 (first at x=2, y=3, z=1); float64 values that large overflow "
      "the differences and gradients an isosurface is computed from: scale the samples";
  EXPECT_EQ(message_of<InputError>([&] { check_finite(view, "d"); }), want);
  EXPECT_EQ(message_of<InputError>([&] { finite_value_range(view, "d"); }), want);
  // NaN is named as such where both are there.
  values[1] = std::nan("");
  EXPECT_TRUE(contains(message_of<InputError>([&] { check_finite(view, "d"); }),
                       "d: 1 sample is NaN or Inf (first at x=1, y=0, z=0)"));
  // Float32 samples cannot come near it.
  const std::vector<float> floats(8, std::numeric_limits<float>::max());
  EXPECT_NO_THROW(check_finite(dense_view(floats.data(), ScalarType::Float32, {2, 2, 2}), "f"));
}

TEST(ValueRange, TypesSubviewsAndEmpty) {
  std::vector<std::int16_t> shorts(5 * 4 * 3);
  for (std::size_t i = 0; i < shorts.size(); ++i) shorts[i] = static_cast<std::int16_t>(i * 10);
  shorts[17] = -300;
  const VolumeView view = dense_view(shorts.data(), ScalarType::Int16, {5, 4, 3});
  EXPECT_EQ(value_range(view), (std::pair<double, double>{-300, 590}));
  // Element 17 is sample (2, 3, 0): outside the first brick, inside the second.
  EXPECT_EQ(value_range(subview(view, {{1, 1, 0}, {3, 3, 2}})),
            (std::pair<double, double>{60, 320}));
  EXPECT_EQ(value_range(subview(view, {{1, 1, 0}, {3, 4, 2}})),
            (std::pair<double, double>{-300, 370}));
  EXPECT_EQ(value_range(subview(view, {{0, 0, 0}, {0, 4, 3}})), (std::pair<double, double>{0, 0}));
  EXPECT_EQ(value_range(VolumeView{}), (std::pair<double, double>{0, 0}));

  std::vector<float> floats = {std::nanf(""), 2.5f, -1.0f, std::nanf(""), 7.0f, 0.0f, 1.0f, 3.0f};
  EXPECT_EQ(value_range(dense_view(floats.data(), ScalarType::Float32, {2, 2, 2})),
            (std::pair<double, double>{-1.0, 7.0}));

  const std::vector<std::uint32_t> big = {4000000000u, 1u};
  EXPECT_EQ(value_range(dense_view(big.data(), ScalarType::UInt32, {2, 1, 1})),
            (std::pair<double, double>{1.0, 4000000000.0}));
}

TEST(ValueRange, LargeVolumeIsDeterministic) {
  std::vector<float> v(128 * 64 * 96);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = std::sin(static_cast<float>(i) * 0.001f);
  v[123456] = -2.0f;
  v[654321] = 5.0f;
  const VolumeView view = dense_view(v.data(), ScalarType::Float32, {128, 64, 96});
  const auto r = value_range(view);
  EXPECT_EQ(r, (std::pair<double, double>{-2.0, 5.0}));
  for (int rep = 0; rep < 5; ++rep) EXPECT_EQ(value_range(view), r);
}

// ---------------------------------------------------------------------------------------------
// NRRD

struct NrrdSpec {
  NrrdSpec(int type_, std::vector<std::size_t> sizes_, const void* data_,
           const NrrdEncoding* encoding_ = nrrdEncodingRaw)
      : type(type_), sizes(std::move(sizes_)), data(data_), encoding(encoding_) {}

  int type;
  std::vector<std::size_t> sizes;
  const void* data;
  const NrrdEncoding* encoding;
  std::vector<double> spacing;              // per axis, optional
  std::vector<std::array<double, 3>> dirs;  // per axis, optional (sets a 3-D space)
  std::vector<double> origin;               // optional (sets a 3-D space)
};

void save_nrrd(const std::string& file, const NrrdSpec& spec) {
  Nrrd* n = nrrdNew();
  ASSERT_EQ(nrrdWrap_nva(n, const_cast<void*>(spec.data), spec.type,
                         static_cast<unsigned>(spec.sizes.size()), spec.sizes.data()),
            0);
  if (!spec.spacing.empty()) nrrdAxisInfoSet_nva(n, nrrdAxisInfoSpacing, spec.spacing.data());
  if (!spec.dirs.empty() || !spec.origin.empty()) {
    ASSERT_EQ(nrrdSpaceDimensionSet(n, 3), 0);
  }
  if (!spec.dirs.empty()) {
    double dirs[NRRD_DIM_MAX][NRRD_SPACE_DIM_MAX] = {};
    for (std::size_t a = 0; a < spec.dirs.size(); ++a)
      for (int d = 0; d < 3; ++d) dirs[a][d] = spec.dirs[a][d];
    nrrdAxisInfoSet_nva(n, nrrdAxisInfoSpaceDirection, dirs);
  }
  if (!spec.origin.empty()) {
    ASSERT_EQ(nrrdSpaceOriginSet(n, spec.origin.data()), 0);
  }
  NrrdIoState* nio = nrrdIoStateNew();
  nio->encoding = spec.encoding;
  const int failed = nrrdSave(file.c_str(), n, nio);
  std::string err;
  if (failed) {
    char* e = biffGetDone(NRRD);
    err = e;
    std::free(e);
  }
  nrrdIoStateNix(nio);
  nrrdNix(n);
  ASSERT_EQ(failed, 0) << err;
}

TEST_F(VolumeIo, NrrdAttachedRaw) {
  std::vector<std::uint16_t> values(3 * 4 * 5);
  for (std::size_t i = 0; i < values.size(); ++i)
    values[i] = static_cast<std::uint16_t>(60000 - i * 997);
  const std::string file = path("v.nrrd");
  NrrdSpec spec{nrrdTypeUShort, {3, 4, 5}, values.data()};
  spec.spacing = {0.5, 2, 3.25};
  save_nrrd(file, spec);
  ASSERT_TRUE(contains(read_file(file), "encoding: raw"));

  const Volume v = read_nrrd(file);
  EXPECT_EQ(v.type(), ScalarType::UInt16);
  EXPECT_EQ(v.dims(), (Index3{3, 4, 5}));
  EXPECT_EQ(v.spacing(), (Vec3d{0.5, 2, 3.25}));
  EXPECT_EQ(v.origin(), (Vec3d{0, 0, 0}));
  for (std::size_t i = 0; i < values.size(); ++i)
    EXPECT_EQ(v.data<std::uint16_t>()[i], values[i]) << i;
}

TEST_F(VolumeIo, NrrdAttachedGzipWithSpaceDirections) {
  if (!nrrdEncodingGzip->available()) GTEST_SKIP() << "teem was built without gzip";
  std::vector<float> values(4 * 3 * 2);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = static_cast<float>(i) * 0.5f - 4.0f;
  const std::string file = path("v.nrrd");
  NrrdSpec spec{nrrdTypeFloat, {4, 3, 2}, values.data(), nrrdEncodingGzip};
  spec.dirs = {{{0.25, 0, 0}}, {{0, 3, 4}}, {{0, 0, -2}}};
  spec.origin = {10, -20, 30.5};
  save_nrrd(file, spec);
  ASSERT_TRUE(contains(read_file(file), "encoding: gzip"));

  const Volume v = read_nrrd(file);
  EXPECT_EQ(v.type(), ScalarType::Float32);
  EXPECT_EQ(v.dims(), (Index3{4, 3, 2}));
  EXPECT_EQ(v.spacing(), (Vec3d{0.25, 5, 2}));
  EXPECT_EQ(v.origin(), (Vec3d{10, -20, 30.5}));
  for (std::size_t i = 0; i < values.size(); ++i) EXPECT_EQ(v.data<float>()[i], values[i]) << i;
}

TEST_F(VolumeIo, NrrdDetachedHeader) {
  std::vector<double> values(2 * 2 * 3);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = 1.0 / (1.0 + static_cast<double>(i));
  const std::string header = path("v.nhdr");
  NrrdSpec spec{nrrdTypeDouble, {2, 2, 3}, values.data()};
  spec.spacing = {1.5, 1.5, 0.75};
  save_nrrd(header, spec);
  const std::string text = read_file(header);
  ASSERT_TRUE(contains(text, "data file: ")) << text;
  ASSERT_TRUE(fs::exists(path("v.raw"))) << text;
  EXPECT_EQ(fs::file_size(path("v.raw")), values.size() * sizeof(double));

  const Volume v = read_volume(header);
  EXPECT_EQ(v.type(), ScalarType::Float64);
  EXPECT_EQ(v.dims(), (Index3{2, 2, 3}));
  EXPECT_EQ(v.spacing(), (Vec3d{1.5, 1.5, 0.75}));
  for (std::size_t i = 0; i < values.size(); ++i) EXPECT_EQ(v.data<double>()[i], values[i]) << i;

  // The header alone is not enough.
  fs::remove(path("v.raw"));
  const std::string msg = message_of<InputError>([&] { read_nrrd(header); });
  EXPECT_TRUE(contains(msg, header)) << msg;
  EXPECT_FALSE(contains(msg, "\n")) << msg;
}

TEST_F(VolumeIo, NrrdAxisCountsAndTypes) {
  const std::vector<std::int8_t> values = {-128, -1, 0, 1, 2, 3, 4, 127};
  const std::string file = path("v.nrrd");

  save_nrrd(file, {nrrdTypeChar, {1, 2, 2, 2}, values.data()});
  Volume v = read_nrrd(file);
  EXPECT_EQ(v.type(), ScalarType::Int8);
  EXPECT_EQ(v.dims(), (Index3{2, 2, 2}));
  for (std::size_t i = 0; i < values.size(); ++i) EXPECT_EQ(v.data<std::int8_t>()[i], values[i]);

  // A last axis of size 1 too (as NIfTI and MetaImage take one).
  save_nrrd(file, {nrrdTypeChar, {2, 2, 2, 1}, values.data()});
  v = read_nrrd(file);
  EXPECT_EQ(v.dims(), (Index3{2, 2, 2}));
  for (std::size_t i = 0; i < values.size(); ++i) EXPECT_EQ(v.data<std::int8_t>()[i], values[i]);
  save_nrrd(file, {nrrdTypeChar, {2, 2, 1, 2}, values.data()});
  EXPECT_TRUE(contains(message_of<InputError>([&] { read_nrrd(file); }), "4 axes"));
  // Axes of a sample's components (colour, vectors) are not positions: refused, named.
  const std::string head = "NRRD0004\ntype: int8\ndimension: 3\nencoding: raw\n";
  for (const char* kinds :
       {"sizes: 3 2 2\nkinds: RGB-color space space", "sizes: 2 2 2\nkinds: space 2-vector space",
        "sizes: 2 2 2\nkinds: domain domain list"}) {
    write_file(file, head + kinds + "\n\n" + std::string(kinds[7] == '3' ? 12 : 8, '\1'));
    const std::string msg = message_of<InputError>([&] { read_nrrd(file); });
    EXPECT_TRUE(contains(msg, "a volume needs three axes of space or domain kind")) << msg;
    EXPECT_TRUE(contains(msg, "components of a sample")) << msg;
  }
  write_file(file, head + "sizes: 2 2 2\nkinds: domain space time\n\n" + std::string(8, '\1'));
  EXPECT_EQ(read_nrrd(file).dims(), (Index3{2, 2, 2}));
  save_nrrd(file, {nrrdTypeChar, {4, 2}, values.data()});
  EXPECT_TRUE(contains(message_of<InputError>([&] { read_nrrd(file); }), "2 axes"));

  const std::vector<std::int64_t> longs(8, 5);
  save_nrrd(file, {nrrdTypeLLong, {2, 2, 2}, longs.data()});
  const std::string msg = message_of<InputError>([&] { read_nrrd(file); });
  EXPECT_TRUE(contains(msg, "'long long int' is not supported")) << msg;

  const std::vector<std::int32_t> ints = {-5, 7, 1 << 30, -(1 << 30), 0, 1, 2, 3};
  save_nrrd(file, {nrrdTypeInt, {2, 2, 2}, ints.data()});
  v = read_nrrd(file);
  EXPECT_EQ(v.type(), ScalarType::Int32);
  EXPECT_EQ(v.data<std::int32_t>()[2], 1 << 30);
  EXPECT_EQ(v.spacing(), (Vec3d{1, 1, 1}));
}

TEST_F(VolumeIo, NrrdMalformedHeader) {
  const std::string file = path("bad.nrrd");
  write_file(file, "NRRD0004\ntype: floot\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n" +
                       std::string(32, '\0'));
  std::string msg = message_of<InputError>([&] { read_nrrd(file); });
  EXPECT_EQ(msg.rfind(file + ": not a readable NRRD file: ", 0), 0u) << msg;
  EXPECT_TRUE(contains(msg, "floot")) << msg;
  EXPECT_FALSE(contains(msg, "\n")) << msg;

  write_file(file, "this is not a nrrd file\n");
  msg = message_of<InputError>([&] { read_nrrd(file); });
  EXPECT_TRUE(contains(msg, file)) << msg;
  EXPECT_FALSE(contains(msg, "\n")) << msg;

  const std::string missing = path("missing.nrrd");
  EXPECT_EQ(message_of<IoError>([&] { read_nrrd(missing); }),
            "cannot open " + missing + ": No such file or directory");
}

// An axis's space direction of no length (zero, underflowing, or `none`) gives its samples no
// distance apart: refused. They were read 1 apart, every axis's direction the identity, exit 0.
TEST_F(VolumeIo, NrrdSpaceDirectionsOfNoLengthAreRefused) {
  const std::string file = path("d.nrrd");
  const auto nrrd = [&](const std::string& directions) {
    write_file(file,
               "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nspace: LPS\n"
               "space directions: " +
                   directions + "\nspace origin: (5,6,7)\nencoding: raw\n\n" +
                   std::string(8, '\1'));
  };
  for (const auto& [directions, says] :
       {std::pair{"(0,0,0) (1.2,1.6,0) (0,0,3)",
                  "NRRD axis 1 of 3 has a space direction of no length"},
        std::pair{"(1,0,0) (0,1e-300,0) (0,0,3)",
                  "NRRD axis 2 of 3 has a space direction of no length"},
        std::pair{"(1,0,0) (0,1,0) none", "NRRD axis 3 of 3 has no space direction"}}) {
    SCOPED_TRACE(directions);
    nrrd(directions);
    EXPECT_TRUE(contains(message_of<InputError>([&] { read_nrrd(file); }), says));
    EXPECT_TRUE(contains(message_of<InputError>([&] { read_volume_header(file); }), says));
  }
  nrrd("(0,0.6,0.8) (1.2,1.6,0) (0,0,3)");
  EXPECT_EQ(read_nrrd(file).spacing(), (Vec3d{1, 2, 3}));
}

// Text samples are checked against what teem read: it casts each token through an int (300 in
// a uchar file read 44, -5 read 251) and stops at the first character that is not a digit (1e2
// read 1), exit 0. Good text, commas included, reads as written (MetaImage's: test_image_formats).
TEST_F(VolumeIo, TextSamplesThatAreNotTheirTypesNumbersAreRefused) {
  const std::string file = path("a.nrrd");
  const auto nrrd = [&](const char* type, const std::string& samples) {
    write_file(file, std::string("NRRD0004\ntype: ") + type +
                         "\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n\n" + samples + "\n");
  };
  nrrd("short", "-7 0 , 12 ,40 32767,\n-32768 5 6");
  const Volume v = read_nrrd(file);
  const std::int16_t want[8] = {-7, 0, 12, 40, 32767, -32768, 5, 6};
  for (int i = 0; i < 8; ++i) EXPECT_EQ(v.data<std::int16_t>()[i], want[i]) << i;
  for (const auto& [type, token, says] :
       {std::tuple{"uchar", "300", "is '300', out of the uint8 range (0 to 255)"},
        std::tuple{"uchar", "-5", "is '-5', out of the uint8 range"},
        std::tuple{"uchar", "1e2", "is '1e2', read by the format's library as 1"},
        std::tuple{"short", "2.7", "is '2.7', not an integer, as int16 samples are"},
        std::tuple{"uint", "5000000000",
                   "is '5000000000', out of the uint32 range (0 to 4294967295)"},
        std::tuple{"float", "1.5x", "is '1.5x', not a number"}}) {
    SCOPED_TRACE(token);
    nrrd(type, std::string("1 2 3 4 5 ") + token + " 7 8");
    const std::string msg = message_of<InputError>([&] { read_nrrd(file); });
    EXPECT_TRUE(contains(msg, "NRRD ascii sample 5 (x=1, y=0, z=1) " + std::string(says))) << msg;
  }
}

// Text in several data files, after a line skip and a byte skip in each (teem skips both in
// every file and reads an equal share from each): checked file by file, as one file is (300
// read 44 there too, exit 0).
TEST_F(VolumeIo, TextSamplesInSeveralDataFilesAndAfterSkipsAreChecked) {
  const std::string file = path("m.nrrd");
  write_file(file,
             "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n"
             "line skip: 1\nbyte skip: 2\ndata file: LIST\na.txt\nb.txt\n");
  const auto data = [&](const std::string& a, const std::string& b) {
    write_file(path("a.txt"), "first line\n: " + a + "\n");
    write_file(path("b.txt"), "first line\n: " + b + "\n");
  };
  data("1 2 3 4", "5 6 7 8");
  const Volume v = read_nrrd(file);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(v.data<std::uint8_t>()[i], i + 1) << i;
  data("1 2 3 4", "5 6 300 8");
  std::string msg = message_of<InputError>([&] { read_nrrd(file); });
  EXPECT_TRUE(contains(msg, "b.txt: NRRD ascii sample 6 (x=0, y=1, z=1) is '300', out of the"))
      << msg;
  data("1 2 3 1e2", "5 6 7 8");
  msg = message_of<InputError>([&] { read_nrrd(file); });
  EXPECT_TRUE(contains(msg, "a.txt: NRRD ascii sample 3 (x=1, y=1, z=0) is '1e2'")) << msg;
  // One detached file after a byte skip alone.
  write_file(file,
             "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n"
             "byte skip: 3\ndata file: a.txt\n");
  write_file(path("a.txt"), "xx\n1 2 3 4 5 6 7 -5\n");
  msg = message_of<InputError>([&] { read_nrrd(file); });
  EXPECT_TRUE(contains(msg, "a.txt: NRRD ascii sample 7 (x=1, y=1, z=1) is '-5'")) << msg;
}

TEST_F(VolumeIo, NrrdNonFinite) {
  std::vector<float> values(8, 1.0f);
  values[5] = std::numeric_limits<float>::infinity();
  const std::string file = path("v.nrrd");
  save_nrrd(file, {nrrdTypeFloat, {2, 2, 2}, values.data()});
  EXPECT_TRUE(contains(message_of<InputError>([&] { read_nrrd(file); }),
                       "1 sample is NaN or Inf (first at x=1, y=0, z=1)"));
}

// ---------------------------------------------------------------------------------------------
// OpenVDB

class Vdb : public VolumeIo {
 protected:
  static void SetUpTestSuite() { openvdb::initialize(); }
  void write(const std::string& file, const openvdb::GridPtrVec& grids) {
    openvdb::io::File out(file);
    out.write(grids);
    out.close();
  }
};

TEST_F(Vdb, FloatGridDensifiesActiveBox) {
  auto grid = openvdb::FloatGrid::create(0.25f);
  grid->setName("density");
  auto transform = openvdb::math::Transform::createLinearTransform(0.5);
  transform->postTranslate(openvdb::Vec3d(10, 20, 30));
  grid->setTransform(transform);
  auto acc = grid->getAccessor();
  acc.setValueOn(openvdb::Coord(-2, 3, 5), 1.5f);
  acc.setValueOn(openvdb::Coord(1, 4, 5), 2.5f);
  acc.setValueOn(openvdb::Coord(0, 3, 7), -1.0f);
  // Inactive but not background: the grid reports 9 there, so the volume must too.
  acc.setValueOff(openvdb::Coord(-1, 4, 6), 9.0f);
  const std::string file = path("v.vdb");
  write(file, {grid});

  const Volume v = read_vdb(file);
  EXPECT_EQ(v.type(), ScalarType::Float32);
  ASSERT_EQ(v.dims(), (Index3{4, 2, 3}));
  EXPECT_EQ(v.spacing(), (Vec3d{0.5, 0.5, 0.5}));
  EXPECT_EQ(v.origin(), (Vec3d{9, 21.5, 32.5}));
  const VolumeView view = v.view();
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 4; ++i) {
        double expected = 0.25;
        if (i == 0 && j == 0 && k == 0) expected = 1.5;
        if (i == 3 && j == 1 && k == 0) expected = 2.5;
        if (i == 2 && j == 0 && k == 2) expected = -1.0;
        if (i == 1 && j == 1 && k == 1) expected = 9.0;
        EXPECT_EQ(view.value(i, j, k), expected) << i << "," << j << "," << k;
      }
}

TEST_F(Vdb, DoubleGridAfterOtherGrids) {
  auto ints = openvdb::Int32Grid::create(0);
  ints->setName("density");
  ints->getAccessor().setValueOn(openvdb::Coord(0, 0, 0), 3);
  auto doubles = openvdb::DoubleGrid::create(-1.0);
  doubles->setName("density");  // same name: must still read this grid, not the first
  auto acc = doubles->getAccessor();
  acc.setValueOn(openvdb::Coord(100, 0, 0), 0.125);
  acc.setValueOn(openvdb::Coord(101, 1, 0), 1e100);  // no float holds it
  const std::string file = path("v.vdb");
  write(file, {ints, doubles});

  const Volume v = read_volume(file);
  EXPECT_EQ(v.type(), ScalarType::Float64);
  ASSERT_EQ(v.dims(), (Index3{2, 2, 1}));
  EXPECT_EQ(v.origin(), (Vec3d{100, 0, 0}));
  EXPECT_EQ(v.spacing(), (Vec3d{1, 1, 1}));
  EXPECT_EQ(v.data<double>()[0], 0.125);
  EXPECT_EQ(v.data<double>()[1], -1.0);
  EXPECT_EQ(v.data<double>()[2], -1.0);
  EXPECT_EQ(v.data<double>()[3], 1e100);
}

TEST_F(Vdb, NotAVdbFile) {
  const std::string file = path("v.vdb");
  write_file(file, "definitely not an OpenVDB file, just some text that is long enough\n");
  const std::string msg = message_of<InputError>([&] { read_vdb(file); });
  EXPECT_EQ(msg.rfind(file + ": not a readable OpenVDB file: ", 0), 0u) << msg;

  const std::string missing = path("missing.vdb");
  EXPECT_EQ(message_of<IoError>([&] { read_vdb(missing); }),
            "cannot open " + missing + ": No such file or directory");
}

TEST_F(Vdb, OnlyIntegerGrid) {
  auto ints = openvdb::Int32Grid::create(0);
  ints->setName("labels");
  ints->getAccessor().setValueOn(openvdb::Coord(1, 2, 3), 4);
  const std::string file = path("v.vdb");
  write(file, {ints});
  const std::string msg = message_of<InputError>([&] { read_vdb(file); });
  EXPECT_EQ(msg, file + ": no float or double grid; found 'labels' (int32)");
}

TEST_F(Vdb, NoActiveVoxels) {
  auto grid = openvdb::FloatGrid::create(1.0f);
  grid->setName("empty");
  const std::string file = path("v.vdb");
  write(file, {grid});
  EXPECT_EQ(message_of<InputError>([&] { read_vdb(file); }),
            file + ": grid 'empty' has no active voxels");
}

TEST_F(Vdb, NonFinite) {
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->getAccessor().setValueOn(openvdb::Coord(0, 0, 0), 1.0f);
  grid->getAccessor().setValueOn(openvdb::Coord(2, 1, 1), std::numeric_limits<float>::quiet_NaN());
  const std::string file = path("v.vdb");
  write(file, {grid});
  const std::string msg = message_of<InputError>([&] { read_vdb(file); });
  EXPECT_TRUE(contains(msg, "1 sample is NaN or Inf (first at x=2, y=1, z=1)")) << msg;
}

// ---------------------------------------------------------------------------------------------
// read_volume dispatch

TEST_F(VolumeIo, ReadVolumeDispatchesAndOverrides) {
  const std::vector<std::uint8_t> bytes = {1, 2, 3, 4, 5, 6, 7, 8};
  const std::string raw = path("r_2x2x2_uint8.raw");
  write_file(raw, bytes.data(), bytes.size());
  RawOptions options;
  options.spacing = Vec3d{2, 3, 4};
  options.origin = Vec3d{-1, -2, -3};
  Volume v = read_volume(raw, options);
  EXPECT_EQ(v.data<std::uint8_t>()[7], 8);
  EXPECT_EQ(v.spacing(), (Vec3d{2, 3, 4}));
  EXPECT_EQ(v.origin(), (Vec3d{-1, -2, -3}));

  // Upper-case extensions are NRRD too; the options override what the header says.
  const std::string nrrd = path("N.NRRD");
  NrrdSpec spec{nrrdTypeUChar, {2, 2, 2}, bytes.data()};
  spec.spacing = {7, 7, 7};
  save_nrrd(nrrd, spec);
  v = read_volume(nrrd, options);
  EXPECT_EQ(v.type(), ScalarType::UInt8);
  EXPECT_EQ(v.data<std::uint8_t>()[3], 4);
  EXPECT_EQ(v.spacing(), (Vec3d{2, 3, 4}));
  EXPECT_EQ(v.origin(), (Vec3d{-1, -2, -3}));
  EXPECT_EQ(read_volume(nrrd).spacing(), (Vec3d{7, 7, 7}));

  RawOptions dims;
  dims.dims = Index3{2, 2, 2};
  EXPECT_TRUE(contains(message_of<InputError>([&] { read_volume(nrrd, dims); }),
                       "apply only to raw files"));
}

// Positions are float32: how finely they hold a grid, per coordinate (an axis of tiny cells at 0
// stays fine beside wide ones), in the grid frame and in a rotated world frame; past float32's
// range, or with cells narrower than a float32 step, the grid is refused.
TEST(GridGeometry, Float32PositionsHoldTheGridOrItIsRefused) {
  const Index3 n{41, 41, 41};
  const Vec3d unit{1, 1, 1};
  EXPECT_EQ(position_resolution(n, unit, {5e6, 5e6, 0}, std::nullopt).steps, 2);  // 2^22..2^23
  EXPECT_EQ(position_resolution(n, unit, {1e6, 0, 0}, std::nullopt).steps, 16);
  EXPECT_EQ(position_resolution(n, unit, {0, 0, 0}, std::nullopt).steps, std::ldexp(1.0, 18));
  EXPECT_GT(position_resolution(n, {1e-6, 1, 1}, {0, 0, 0}, std::nullopt).steps, 1e5);
  // A world frame 5e6 from 0, rotated a quarter turn about z: its rows mix the grid's axes.
  const WorldFrame far{{5e6, 0, 0}, {0, -1, 0, 1, 0, 0, 0, 0, 1}};
  EXPECT_EQ(position_resolution(n, unit, {0, 0, 0}, far).steps, 2);
  std::vector<std::string> lines;
  const Warn heard = [&](const std::string& line) { lines.push_back(line); };
  warn_coarse_positions(n, unit, {0, 0, 0}, std::nullopt, heard);
  warn_coarse_positions(n, unit, {5e5, 0, 0}, std::nullopt, heard);  // 32 steps
  EXPECT_TRUE(lines.empty());
  warn_coarse_positions(n, unit, {0, 0, 0}, far, heard);
  ASSERT_EQ(lines.size(), 1u);
  const std::string& said = lines[0];
  EXPECT_EQ(said.rfind("positions are float32: at the grid's coordinates of up to 5e+06 a "
                       "float32 steps by 0.5, against cells 1 wide, so vertices snap to a lattice "
                       "of about 2 steps per cell",
                       0),
            0u)
      << said;
  EXPECT_NO_THROW(check_grid_geometry(n, unit, {5e6, 5e6, 0}, far, "v"));  // coarse, not refused
  auto refused = [&](const Vec3d& spacing, const Vec3d& origin,
                     const std::optional<WorldFrame>& world) {
    try {
      check_grid_geometry(n, spacing, origin, world, "v");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(refused({1e37, 1, 1}, {0, 0, 0}, std::nullopt),
            "v: the grid's coordinates reach 4e+38, beyond the largest float32 (3.40282e+38), in "
            "which positions are written");
  EXPECT_EQ(refused(unit, {0, 0, 0}, WorldFrame{{1e39, 0, 0}, kIdentity3})
                .rfind("v: the grid's coordinates reach 1e+39, beyond the largest float32", 0),
            0u);
  EXPECT_EQ(refused({1e-9, 1, 1}, {1, 0, 0}, std::nullopt),
            "v: the grid's cells, 1e-09 wide, are narrower than a float32 step (1.19209e-07) at "
            "its coordinates of up to 1, in which positions are written: the mesh would collapse");
  EXPECT_EQ(
      refused({1e-300, 1, 1}, {0, 0, 0}, std::nullopt).rfind("v: the grid's cells, 1e-300", 0), 0u);
}

TEST(ReadVolume, ProceduralField) {
  const Volume v = read_volume("field:sphere:9");
  EXPECT_EQ(v.type(), ScalarType::Float32);
  EXPECT_EQ(v.dims(), (Index3{9, 9, 9}));
  EXPECT_EQ(v.spacing(), (Vec3d{1, 1, 1}));
  EXPECT_EQ(v.origin(), (Vec3d{0, 0, 0}));
  // Centre sample (u = 0) lies 0.75 inside the sphere of radius 0.75.
  EXPECT_NEAR(v.view().value(4, 4, 4), 0.75, 1e-6);
  EXPECT_THROW(read_volume("field:nosuchfield:8"), InputError);
}

// ---------------------------------------------------------------------------------------------
// Real volumes

void check_real_volume(const std::string& file, const Index3& dims) {
  const Volume v = read_volume(file);
  EXPECT_EQ(v.type(), ScalarType::UInt8);
  ASSERT_EQ(v.dims(), dims);
  const std::string expected = inflate_gzip(read_file(file));
  ASSERT_EQ(expected.size(), v.byte_size());
  EXPECT_EQ(std::memcmp(v.bytes(), expected.data(), expected.size()), 0);
  const auto [lo, hi] = value_range(v.view());
  const auto [min_it, max_it] = std::minmax_element(
      expected.begin(), expected.end(),
      [](char a, char b) { return static_cast<unsigned char>(a) < static_cast<unsigned char>(b); });
  EXPECT_EQ(lo, static_cast<unsigned char>(*min_it));
  EXPECT_EQ(hi, static_cast<unsigned char>(*max_it));
  EXPECT_LT(lo, hi);  // a real scan is not constant
}

TEST(RealVolumes, SharedBucky) {
  const fs::path file = fs::path(ISOTILE_SHARED_DATA) / "bucky_32x32x32_uint8.raw.gz";
  ISOTILE_REQUIRE_SHARED(file);
  check_real_volume(file.string(), {32, 32, 32});
  const auto [lo, hi] = value_range(read_volume(file.string()).view());
  EXPECT_EQ(lo, 0);  // as the manifest states
  EXPECT_EQ(hi, 255);
}

TEST(RealVolumes, BundledFixtures) {
  check_real_volume((fs::path(ISOTILE_TEST_DATA) / "bucky_32x32x32_uint8.raw.gz").string(),
                    {32, 32, 32});
  check_real_volume((fs::path(ISOTILE_TEST_DATA) / "nucleon_41x41x41_uint8.raw.gz").string(),
                    {41, 41, 41});
}

}  // namespace
}  // namespace isotile
