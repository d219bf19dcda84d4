// MRC2014 / CCP4 maps (cryo-EM, crystallography), following the MRC2014 specification
// (https://www.ccpem.ac.uk/mrc_format/mrc2014.php): a 1024-byte header, an optional extended
// header of NSYMBT bytes, then the samples with columns fastest.
//
// The header is validated against the file's size before anything is allocated. Axis order:
// columns, rows and sections run along the axes MAPC, MAPR and MAPS (1 = X, 2 = Y, 3 = Z); the
// volume is returned in X, Y, Z order. Voxel size = cell length / MX (MY, MZ). The first sample
// lies at ORIGIN + start * voxel size, where start is NXSTART, NYSTART, NZSTART taken through
// the same axis order (cryo-EM maps put the offset in ORIGIN, crystallographic maps in the start
// fields; where both are given they add). Non-orthogonal cells (angles other than 90 degrees)
// become the volume's direction cosines.
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/volume/volume_io.h"

namespace isotile {

namespace {

constexpr std::size_t kHeaderBytes = 1024;
// deflate shrinks data by at most about 1032:1 (as in image_headers.cpp).
constexpr std::uint64_t kMaxDeflateRatio = 1032;

// gzip'd maps (.map.gz, as EMDB distributes them) are recognised by their first bytes.
bool is_gzip(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  unsigned char b[2] = {};
  return f.read(reinterpret_cast<char*>(b), 2) && b[0] == 0x1f && b[1] == 0x8b;
}

struct GzCloser {
  void operator()(gzFile f) const { gzclose_r(f); }
};
using GzFile = std::unique_ptr<gzFile_s, GzCloser>;

GzFile open_gz(const std::string& path) {
  errno = 0;
  GzFile f(gzopen(path.c_str(), "rb"));
  if (!f)
    throw IoError("cannot open " + path + ": " + (errno ? std::strerror(errno) : "out of memory"));
  gzbuffer(f.get(), 1u << 20);
  return f;
}

// Up to n bytes from a gzip stream; InputError for corrupt or cut-off data.
std::size_t gz_read(const std::string& path, gzFile f, void* out, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const auto want = static_cast<unsigned>(std::min<std::size_t>(n - done, 1u << 30));
    const int got = gzread(f, static_cast<char*>(out) + done, want);
    int code = Z_OK;
    const char* message = gzerror(f, &code);
    if (got < 0 || (code != Z_OK && code != Z_BUF_ERROR)) {
      if (code == Z_ERRNO) throw IoError("cannot read " + path + ": " + std::strerror(errno));
      throw InputError(path + ": corrupt gzip data (" + gzerror_text(path, message) + ")");
    }
    // zlib says Z_BUF_ERROR where its look-ahead found the file's end, also after handing over
    // every byte asked for (a stream cut in its trailer): the trailer check below says that.
    if (code == Z_BUF_ERROR && static_cast<unsigned>(got) < want)
      throw InputError(path + ": gzip data cut off after " + std::to_string(done + got) +
                       " bytes of the " + std::to_string(n) + " expected here (truncated file)");
    done += static_cast<std::size_t>(got);
    if (static_cast<unsigned>(got) < want) break;
  }
  return done;
}

struct MrcLayout {
  VolumeHeader header;
  std::int64_t n[3];  // columns, rows, sections as stored
  int axis[3];        // volume axis (0 X, 1 Y, 2 Z) of columns, rows, sections
  int mode = 2;
  bool swap = false;
  bool gzip = false;
  std::uint64_t offset = 0;
  std::uint64_t bytes = 0;  // of samples, as stored
};

template <class T>
T get(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

float half_to_float(std::uint16_t h) {
  const std::uint32_t sign = (h & 0x8000u) << 16;
  std::uint32_t exp = (h >> 10) & 0x1f, mant = h & 0x3ff;
  std::uint32_t bits;
  if (exp == 0x1f) {
    bits = sign | 0x7f800000u | (mant << 13);
  } else if (exp == 0) {
    if (mant == 0) {
      bits = sign;
    } else {
      int e = -1;
      do {
        ++e;
        mant <<= 1;
      } while (!(mant & 0x400));
      bits = sign | static_cast<std::uint32_t>(127 - 15 - e) << 23 | (mant & 0x3ff) << 13;
    }
  } else {
    bits = sign | (exp + 127 - 15) << 23 | mant << 13;
  }
  return std::bit_cast<float>(bits);
}

// IMOD's stamp (word 39) in the header's byte order, as an int32: "IMOD" in ASCII.
constexpr std::int32_t kImodStamp = 1146047817;

MrcLayout mrc_layout(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError("cannot open " + path + ": " + std::strerror(errno));
  std::error_code ec;
  const std::uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) throw IoError("cannot open " + path + ": " + ec.message());
  MrcLayout m;
  m.gzip = is_gzip(path);
  unsigned char h[kHeaderBytes];
  std::size_t got = 0;
  if (m.gzip) {
    const GzFile gz = open_gz(path);
    got = gz_read(path, gz.get(), h, kHeaderBytes);
  } else {
    f.read(reinterpret_cast<char*>(h), kHeaderBytes);
    got = static_cast<std::size_t>(f.gcount());
  }
  if (got != kHeaderBytes)
    throw InputError(path + ": MRC header truncated (" + std::to_string(got) + " of 1024 bytes)");
  // MACHST says the byte order; old files leave it empty, so a plausible mode decides then.
  const bool little_stamp = h[212] == 0x44 && (h[213] == 0x41 || h[213] == 0x44);
  const bool big_stamp = h[212] == 0x11 && h[213] == 0x11;
  const bool native_little = std::endian::native == std::endian::little;
  if (little_stamp || big_stamp) {
    m.swap = little_stamp != native_little;
  } else {
    const auto mode_ok = [&](bool s) {
      const std::int32_t mode = get<std::int32_t>(h + 12, s);
      return mode >= 0 && mode <= 16;
    };
    m.swap = !mode_ok(false) && mode_ok(true);
  }
  const auto i32 = [&](std::size_t at) { return get<std::int32_t>(h + at, m.swap); };
  const auto f32 = [&](std::size_t at) { return static_cast<double>(get<float>(h + at, m.swap)); };
  m.mode = i32(12);
  ScalarType type;
  std::size_t stored = 0;
  switch (m.mode) {
    case 0:
      // Signed bytes in MRC2014; IMOD writes its mode 0 maps unsigned and says so by its stamp
      // with bit 0 of its flags clear (as IMOD, ChimeraX and the MRC2014 notes read them).
      type = i32(152) == kImodStamp && (i32(156) & 1) == 0 ? ScalarType::UInt8 : ScalarType::Int8;
      stored = 1;
      break;
    case 1:
      type = ScalarType::Int16;
      stored = 2;
      break;
    case 2:
      type = ScalarType::Float32;
      stored = 4;
      break;
    case 6:
      type = ScalarType::UInt16;
      stored = 2;
      break;
    case 12:
      type = ScalarType::Float32;  // half floats, widened
      stored = 2;
      break;
    default:
      throw InputError(path + ": MRC mode " + std::to_string(m.mode) +
                       " is not supported (0 int8, 1 int16, 2 float32, 6 uint16, 12 float16; "
                       "complex modes 3 and 4 are not volumes of values)");
  }
  const int map[3] = {i32(64), i32(68), i32(72)};
  bool seen[3] = {false, false, false};
  for (int c = 0; c < 3; ++c) {
    if (map[c] < 1 || map[c] > 3 || seen[map[c] - 1])
      throw InputError(path + ": MRC axis order MAPC, MAPR, MAPS = " + std::to_string(map[0]) +
                       ", " + std::to_string(map[1]) + ", " + std::to_string(map[2]) +
                       " is not a permutation of 1, 2, 3");
    seen[map[c] - 1] = true;
    m.axis[c] = map[c] - 1;
  }
  Index3 dims{};
  Vec3d start{};
  for (int c = 0; c < 3; ++c) {
    m.n[c] = i32(4 * c);
    if (m.n[c] <= 0)
      throw InputError(path + ": MRC size " + std::to_string(m.n[c]) + " along " +
                       (c == 0   ? "columns"
                        : c == 1 ? "rows"
                                 : "sections") +
                       " (must be positive)");
    dims[m.axis[c]] = m.n[c];
    start[m.axis[c]] = i32(16 + 4 * c);
  }
  // ISPG 401 to 630: a stack of volumes of MZ sections each, NZ = MZ x volumes (MRC2014). Read
  // as one, they would be laid end to end along z.
  const std::int32_t ispg = i32(88), mz = i32(36);
  if (ispg >= 401 && ispg <= 630 && mz > 0 && mz != dims[2])
    throw InputError(path + ": an MRC stack of " +
                     (dims[2] % mz == 0 ? std::to_string(dims[2] / mz) + " volumes"
                                        : "volumes (" + std::to_string(dims[2]) + " along z)") +
                     " of " + std::to_string(mz) + " sections each (space group ISPG " +
                     std::to_string(ispg) +
                     "), not one volume; cut the one to extract out first (e.g. IMOD's newstack, "
                     "or mrcfile)");
  // ISPG 0 is an image or a stack of images (MRC2014), and `.mrcs` the name cryo-EM software
  // (RELION) gives stacks of 2-D particle images: read as a volume, its images would
  // be laid one on another along z. A volume written with ISPG 0 under another name is read.
  const std::string name = ascii_lower(std::filesystem::path(path).filename().string());
  if (ispg == 0 && dims[2] > 1 && (name.ends_with(".mrcs") || name.ends_with(".mrcs.gz")))
    throw InputError(path + ": a stack of " + std::to_string(m.n[2]) +
                     " 2-D images (.mrcs, space group ISPG 0), not a volume; if it holds one "
                     "volume, name it .mrc");
  const std::int32_t nsymbt = i32(92);
  if (nsymbt < 0)
    throw InputError(path + ": MRC extended header size NSYMBT is " + std::to_string(nsymbt));
  const std::uint64_t bytes = checked_volume_bytes(type, dims) / scalar_size(type) * stored;
  m.offset = kHeaderBytes + static_cast<std::uint64_t>(nsymbt);
  m.bytes = bytes;
  // A gzip'd map's size is known only once inflated (read_mrc checks it): here only that the
  // compressed bytes could hold it, before anything is allocated.
  if (m.gzip && size * kMaxDeflateRatio < m.offset + bytes)
    throw InputError(path + ": " + std::to_string(size) + " compressed bytes cannot hold the " +
                     std::to_string(m.offset + bytes) + " bytes the MRC header (" +
                     std::to_string(m.n[0]) + "x" + std::to_string(m.n[1]) + "x" +
                     std::to_string(m.n[2]) + ", mode " + std::to_string(m.mode) + ") says");
  if (!m.gzip && size != m.offset + bytes)
    throw InputError(path + ": file holds " + std::to_string(size) + " bytes but the MRC header (" +
                     std::to_string(m.n[0]) + "x" + std::to_string(m.n[1]) + "x" +
                     std::to_string(m.n[2]) + ", mode " + std::to_string(m.mode) + ", " +
                     std::to_string(nsymbt) + " extended header bytes) says " +
                     std::to_string(m.offset + bytes));
  VolumeHeader& v = m.header;
  v.format = "MRC";
  v.type = type;
  v.dims = dims;
  const std::int32_t sampling[3] = {i32(28), i32(32), i32(36)};
  // A cell length or angle of 0 is a field left unset (common in maps written by older tools):
  // 1 per voxel and 90 degrees, as for MX 0. Anything else that cannot be a cell (negative,
  // NaN, angles of 180 or more) and a non-finite ORIGIN are refused: MRC2014 has no "unknown"
  // value for them, and a made-up one would place the mesh wrongly with exit status 0.
  static const char* const kAxis[3] = {"X", "Y", "Z"};
  for (int a = 0; a < 3; ++a) {
    const double cell = f32(40 + 4 * a);
    if (!std::isfinite(cell) || cell < 0)
      throw InputError(path + ": MRC cell length along " + kAxis[a] + " is " + short_number(cell) +
                       " (must be finite and not negative)");
    v.spacing[a] = 1;
    if (sampling[a] > 0 && cell > 0) v.spacing[a] = cell / sampling[a];
  }
  double angle[3];
  static const char* const kAngle[3] = {"alpha", "beta", "gamma"};
  for (int a = 0; a < 3; ++a) {
    angle[a] = f32(52 + 4 * a);
    if (!std::isfinite(angle[a]) || angle[a] < 0 || angle[a] >= 180)
      throw InputError(path + ": MRC cell angle " + kAngle[a] + " is " + short_number(angle[a]) +
                       " degrees (must be above 0 and below 180, or 0 for unset)");
    if (angle[a] == 0) angle[a] = 90;
  }
  const Vec3d origin{f32(196), f32(200), f32(204)};
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(origin[a]))
      throw InputError(path + ": MRC ORIGIN along " + kAxis[a] + " is " + short_number(origin[a]) +
                       " (must be finite)");
  for (int a = 0; a < 3; ++a) v.origin[a] = origin[a] + start[a] * v.spacing[a];
  if (angle[0] != 90 || angle[1] != 90 || angle[2] != 90) {
    // Cell axes a, b, c in Cartesian coordinates (a along x, b in the x-y plane).
    const double rad = M_PI / 180;
    const double ca = std::cos(angle[0] * rad), cb = std::cos(angle[1] * rad),
                 cg = std::cos(angle[2] * rad), sg = std::sin(angle[2] * rad);
    const double cy = (ca - cb * cg) / sg;
    const double cz2 = 1 - cb * cb - cy * cy;
    if (cz2 <= 0) throw InputError(path + ": MRC cell angles do not form a cell");
    const Mat3 d{1, cg, cb, 0, sg, cy, 0, 0, std::sqrt(cz2)};
    WorldFrame w;
    w.direction = d;
    // The start offset runs along the cell's axes too.
    for (int r = 0; r < 3; ++r)
      w.origin[r] = origin[r] + d[3 * r] * start[0] * v.spacing[0] +
                    d[3 * r + 1] * start[1] * v.spacing[1] + d[3 * r + 2] * start[2] * v.spacing[2];
    v.world = w;
  }
  const bool in_order = m.axis[0] == 0 && m.axis[1] == 1 && m.axis[2] == 2;
  if (in_order && m.mode != 12 && !m.gzip)
    v.plain = PlainData{path, m.offset, type, dims,
                        m.swap != !native_little ? Endian::Big : Endian::Little};
  return m;
}

}  // namespace

VolumeHeader read_mrc_header(const std::string& path) {
  return mrc_layout(path).header;
}

Volume read_mrc(const std::string& path, Progress* progress) {
  const MrcLayout m = mrc_layout(path);
  const VolumeHeader& h = m.header;
  Volume volume(h.type, h.dims, h.spacing, h.origin);
  volume.set_world(h.world);
  std::ifstream f;
  GzFile gz;
  if (m.gzip) {
    gz = open_gz(path);
    std::vector<unsigned char> skip(
        static_cast<std::size_t>(std::min<std::uint64_t>(m.offset, 1u << 20)));
    for (std::uint64_t left = m.offset; left > 0;) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(left, skip.size()));
      if (gz_read(path, gz.get(), skip.data(), n) != n)
        throw InputError(path + ": decompresses to fewer bytes than the MRC header's " +
                         std::to_string(m.offset) + " header bytes");
      left -= n;
    }
  } else {
    f.open(path, std::ios::binary);
    if (!f) throw IoError("cannot open " + path + ": " + std::strerror(errno));
    f.seekg(static_cast<std::streamoff>(m.offset));
  }
  const std::size_t stored = m.mode == 12 ? 2 : scalar_size(h.type);
  const std::size_t out_size = scalar_size(h.type);
  // One section at a time, scattered into X, Y, Z order.
  const std::size_t section = static_cast<std::size_t>(m.n[0] * m.n[1]);
  std::vector<unsigned char> buf(section * stored);
  Index3 stride{1, h.dims[0], h.dims[0] * h.dims[1]};
  const std::int64_t sc = stride[m.axis[0]], sr = stride[m.axis[1]], ss = stride[m.axis[2]];
  auto* out = reinterpret_cast<unsigned char*>(volume.bytes());
  progress_begin(progress, Stage::Read, m.n[2]);  // in sections
  for (std::int64_t s = 0; s < m.n[2]; ++s) {
    if (s > 0) progress_advance(progress);
    if (m.gzip) {
      const std::size_t got = gz_read(path, gz.get(), buf.data(), buf.size());
      if (got != buf.size())
        throw InputError(
            path + ": decompresses to " +
            std::to_string(m.offset + static_cast<std::uint64_t>(s) * buf.size() + got) +
            " bytes but the MRC header (" + std::to_string(m.n[0]) + "x" + std::to_string(m.n[1]) +
            "x" + std::to_string(m.n[2]) + ", mode " + std::to_string(m.mode) + ") says " +
            std::to_string(m.offset + m.bytes) + " (too short)");
    } else {
      f.read(reinterpret_cast<char*>(buf.data()), static_cast<std::streamsize>(buf.size()));
      if (static_cast<std::size_t>(f.gcount()) != buf.size())
        throw IoError("cannot read " + path + ": file is shorter than its header says");
    }
    for (std::int64_t r = 0; r < m.n[1]; ++r)
      for (std::int64_t c = 0; c < m.n[0]; ++c) {
        const unsigned char* src = buf.data() + static_cast<std::size_t>(r * m.n[0] + c) * stored;
        unsigned char* dst = out + static_cast<std::size_t>(c * sc + r * sr + s * ss) * out_size;
        if (m.mode == 12) {
          const float v = half_to_float(get<std::uint16_t>(src, m.swap));
          std::memcpy(dst, &v, 4);
        } else {
          std::memcpy(dst, src, stored);
          if (m.swap) std::reverse(dst, dst + stored);
        }
      }
  }
  progress_advance(progress);
  if (m.gzip) {
    // Reading on also makes zlib check the gzip trailer (CRC and length).
    char extra;
    const int got = gzread(gz.get(), &extra, 1);
    int code = Z_OK;
    const char* message = gzerror(gz.get(), &code);
    if (got == 1)
      throw InputError(path + ": decompresses to more than the " +
                       std::to_string(m.offset + m.bytes) +
                       " bytes the MRC header says (too long)");
    if (code == Z_BUF_ERROR)
      throw InputError(path + ": gzip data cut off: all " + std::to_string(m.offset + m.bytes) +
                       " bytes are there but the stream's end (CRC and length) is cut off "
                       "(truncated file)");
    if (got < 0 || code != Z_OK)
      throw InputError(path + ": corrupt gzip data (" + gzerror_text(path, message) + ")");
  }
  check_finite(volume.view(), path);
  return volume;
}

}  // namespace isotile
