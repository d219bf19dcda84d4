// NIfTI-1/2 and MetaImage headers, read and checked without ITK.
#include "core/volume/image_headers.h"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "core/errors.h"

namespace isotile {

namespace {

namespace fs = std::filesystem;

// deflate cannot shrink data by more than about 1032:1: a compressed file much smaller than
// that of the samples its header claims is corrupt, and must not make anyone allocate them.
constexpr std::uint64_t kMaxDeflateRatio = 1032;

std::uint64_t file_size_of(const std::string& path) {
  std::error_code ec;
  const std::uintmax_t n = fs::file_size(path, ec);
  if (ec) throw IoError("cannot open " + path + ": " + ec.message());
  return n;
}

std::string dims_text(const Index3& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

template <class T>
T get(const unsigned char* p, bool swap) {
  T v;
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  std::memcpy(&v, b, sizeof(T));
  return v;
}

std::optional<ScalarType> nifti_type(int datatype) {
  switch (datatype) {
    case 2:
      return ScalarType::UInt8;
    case 4:
      return ScalarType::Int16;
    case 8:
      return ScalarType::Int32;
    case 16:
      return ScalarType::Float32;
    case 64:
      return ScalarType::Float64;
    case 256:
      return ScalarType::Int8;
    case 512:
      return ScalarType::UInt16;
    case 768:
      return ScalarType::UInt32;
    default:
      return std::nullopt;
  }
}

bool ends_with_ci(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (std::size_t i = 0; i < suffix.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) != suffix[i])
      return false;
  return true;
}

}  // namespace

ImageHeaderCheck check_nifti_header(const std::string& path) {
  const bool gz = ends_with_ci(path, ".gz");
  const std::uint64_t size = file_size_of(path);
  std::array<unsigned char, 540> h{};
  std::size_t got = 0;
  if (gz) {
    gzFile f = gzopen(path.c_str(), "rb");
    if (!f) throw IoError("cannot open " + path + ": " + std::strerror(errno));
    const int n = gzread(f, h.data(), static_cast<unsigned>(h.size()));
    gzclose(f);
    got = n > 0 ? static_cast<std::size_t>(n) : 0;
  } else {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw IoError("cannot open " + path + ": " + std::strerror(errno));
    f.read(reinterpret_cast<char*>(h.data()), static_cast<std::streamsize>(h.size()));
    got = static_cast<std::size_t>(f.gcount());
  }
  if (got < 348)
    throw InputError(path + ": NIfTI header truncated (" + std::to_string(got) + " bytes)");
  const std::int32_t raw_size = get<std::int32_t>(h.data(), false);
  bool swap = false;
  int version = 0;
  for (bool s : {false, true}) {
    const std::int32_t v = get<std::int32_t>(h.data(), s);
    if (v == 348) version = 1;
    if (v == 540) version = 2;
    if (version) {
      swap = s;
      break;
    }
  }
  if (!version)
    throw InputError(path + ": not a NIfTI file (sizeof_hdr is " + std::to_string(raw_size) +
                     ", expected 348 or 540)");
  if (version == 2 && got < 540) throw InputError(path + ": NIfTI-2 header truncated");
  const unsigned char* magic = version == 1 ? h.data() + 344 : h.data() + 4;
  const bool digit = magic[2] == (version == 1 ? '1' : '2') && magic[3] == '\0';
  const bool single = magic[0] == 'n' && magic[1] == '+' && digit;
  const bool pair = magic[0] == 'n' && magic[1] == 'i' && digit;
  if (!single && !pair) throw InputError(path + ": NIfTI magic string missing");
  if (pair)
    throw InputError(path +
                     ": a NIfTI header whose samples are in a separate .img file; "
                     "convert it to a single .nii");
  std::array<std::int64_t, 8> dim{};
  int datatype = 0, bitpix = 0;
  double vox_offset = 0, slope = 0, inter = 0;
  if (version == 1) {
    for (int i = 0; i < 8; ++i) dim[i] = get<std::int16_t>(h.data() + 40 + 2 * i, swap);
    datatype = get<std::int16_t>(h.data() + 70, swap);
    bitpix = get<std::int16_t>(h.data() + 72, swap);
    vox_offset = get<float>(h.data() + 108, swap);
    slope = get<float>(h.data() + 112, swap);
    inter = get<float>(h.data() + 116, swap);
  } else {
    datatype = get<std::int16_t>(h.data() + 12, swap);
    bitpix = get<std::int16_t>(h.data() + 14, swap);
    for (int i = 0; i < 8; ++i) dim[i] = get<std::int64_t>(h.data() + 16 + 8 * i, swap);
    vox_offset = static_cast<double>(get<std::int64_t>(h.data() + 168, swap));
    slope = get<double>(h.data() + 176, swap);
    inter = get<double>(h.data() + 184, swap);
  }
  // ITK turns qform and sform into a direction matrix through VNL, which aborts the process on
  // non-finite entries; a singular sform gives no direction at all.
  {
    const auto real = [&](std::size_t at1, std::size_t at2) {
      return version == 1 ? static_cast<double>(get<float>(h.data() + at1, swap))
                          : get<double>(h.data() + at2, swap);
    };
    std::array<double, 12> srow{};
    for (int i = 0; i < 12; ++i) srow[i] = real(280 + 4 * i, 400 + 8 * i);
    std::array<double, 6> quat{};
    for (int i = 0; i < 6; ++i) quat[i] = real(256 + 4 * i, 352 + 8 * i);
    // Finite, and within 1e30: VNL's SVD of an sform with entries near float's limit does not
    // converge and ITK waits for it for ever (found by the fuzz replay).
    const auto sane = [](double x) { return std::isfinite(x) && std::abs(x) < 1e30; };
    bool finite = true;
    for (double x : srow) finite = finite && sane(x);
    for (double x : quat) finite = finite && sane(x);
    for (int i = 0; i < 8; ++i) finite = finite && sane(real(76 + 4 * i, 104 + 8 * i));
    if (!finite)
      throw InputError(path +
                       ": NIfTI geometry (pixdim, quatern, qoffset or srow) is not finite or "
                       "beyond 1e30");
    const int sform = version == 1 ? get<std::int16_t>(h.data() + 254, swap)
                                   : get<std::int32_t>(h.data() + 348, swap);
    if (sform > 0) {
      const auto& m = srow;  // rows of 4: the 3x3 part is m[0..2], m[4..6], m[8..10]
      const double det = m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) +
                         m[2] * (m[4] * m[9] - m[5] * m[8]);
      double scale = 1;
      for (int c = 0; c < 3; ++c)
        scale *= std::sqrt(m[c] * m[c] + m[4 + c] * m[4 + c] + m[8 + c] * m[8 + c]);
      if (!(std::abs(det) > 1e-6 * scale) || scale == 0)
        throw InputError(path + ": NIfTI sform matrix is singular");
    }
  }
  if (dim[0] < 2 || dim[0] > 7)
    throw InputError(path + ": NIfTI dim[0] is " + std::to_string(dim[0]) + " (1 to 7 axes)");
  Index3 dims{1, 1, 1};
  for (int a = 1; a <= dim[0]; ++a) {
    if (dim[a] <= 0)
      throw InputError(path + ": NIfTI axis " + std::to_string(a) + " has size " +
                       std::to_string(dim[a]));
    if (a <= 3)
      dims[a - 1] = dim[a];
    else if (dim[a] != 1)
      throw InputError(path + ": NIfTI axis " + std::to_string(a) + " has size " +
                       std::to_string(dim[a]) + "; a volume needs 3 axes (no time series)");
  }
  const std::optional<ScalarType> type = nifti_type(datatype);
  if (!type)
    throw InputError(path + ": NIfTI datatype " + std::to_string(datatype) +
                     " is not supported (int8 to uint32, float or double)");
  if (bitpix != 0 && static_cast<std::size_t>(bitpix) != 8 * scalar_size(*type))
    throw InputError(path + ": NIfTI bitpix " + std::to_string(bitpix) +
                     " does not match datatype " + std::to_string(datatype));
  const std::uint64_t bytes = checked_volume_bytes(*type, dims);
  const std::uint64_t header = version == 1 ? 348 : 540;
  if (!std::isfinite(vox_offset) || vox_offset < static_cast<double>(header) || vox_offset > 1e15)
    throw InputError(path + ": NIfTI vox_offset " + std::to_string(vox_offset) + " is invalid");
  const auto offset = static_cast<std::uint64_t>(vox_offset);
  if (!gz && size < offset + bytes)
    throw InputError(path + ": file holds " + std::to_string(size) + " bytes but " +
                     dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples need " +
                     std::to_string(bytes) + " after " + std::to_string(offset) + " header bytes");
  if (gz && size * kMaxDeflateRatio < bytes)
    throw InputError(path + ": " + std::to_string(size) + " compressed bytes cannot hold " +
                     dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples");
  ImageHeaderCheck out;
  if (gz)
    out.compressed = ImageHeaderCheck::Compressed{
        path, 0, offset + bytes, true,
        dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples after " +
            std::to_string(offset) + " header bytes"};
  if (std::isfinite(slope) && slope != 0 && (slope != 1 || (std::isfinite(inter) && inter != 0))) {
    out.rescaled = true;
    out.rescale_slope = slope;
    out.rescale_intercept = std::isfinite(inter) ? inter : 0;
  }
  // Trailing bytes past the samples are allowed by ITK; box reads want the exact layout.
  if (!gz && !out.rescaled && size == offset + bytes)
    out.plain = PlainData{
        path, offset, *type, dims,
        swap == (std::endian::native == std::endian::little) ? Endian::Big : Endian::Little};
  return out;
}

ImageHeaderCheck check_metaimage_header(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError("cannot open " + path + ": " + std::strerror(errno));
  const std::uint64_t size = file_size_of(path);
  // A header is a few hundred bytes; past 64 KiB without ElementDataFile it is not one.
  constexpr std::uint64_t kMaxHeader = 1 << 16;
  std::string line, data_file;
  int ndims = 0;
  std::vector<std::int64_t> dimsize;
  std::string element_type;
  bool compressed = false, msb = false, found = false;
  std::int64_t header_size = 0, channels = 1;
  std::uint64_t header_end = 0;
  while (std::getline(f, line)) {
    header_end += line.size() + 1;
    if (header_end > kMaxHeader) break;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::size_t eq = line.find('=');
    if (eq == std::string::npos) continue;
    std::string key = line.substr(0, eq), value = line.substr(eq + 1);
    const auto trim = [](std::string& s) {
      s.erase(0, s.find_first_not_of(" \t"));
      s.erase(s.find_last_not_of(" \t") + 1);
    };
    trim(key);
    trim(value);
    std::istringstream v(value);
    if (key == "NDims") {
      if (value.empty() || value.size() > 2 ||
          value.find_first_not_of("0123456789") != std::string::npos)
        throw InputError(path + ": MetaImage NDims is '" + value + "'");
      ndims = std::stoi(value);
    } else if (key == "DimSize") {
      // Whole tokens of digits only: ITK reads "3.4e38" as a number, where >> would stop at 3.
      for (std::string item; v >> item;) {
        if (item.empty() || item.size() > 18 ||
            item.find_first_not_of("0123456789") != std::string::npos)
          throw InputError(path + ": MetaImage DimSize holds '" + item +
                           "', not a positive integer");
        dimsize.push_back(std::stoll(item));
      }
    } else if (key == "ElementType") {
      element_type = value;
    } else if (key == "CompressedData") {
      compressed = value == "True" || value == "true";
    } else if (key == "BinaryDataByteOrderMSB" || key == "ElementByteOrderMSB") {
      msb = value == "True" || value == "true";
    } else if (key == "HeaderSize") {
      v >> header_size;
    } else if (key == "ElementSpacing" || key == "ElementSize" || key == "TransformMatrix" ||
               key == "Rotation" || key == "Orientation" || key == "Offset" || key == "Position" ||
               key == "Origin" || key == "CenterOfRotation") {
      // ITK builds its direction matrix through VNL, which aborts on non-finite entries.
      std::vector<double> values;
      for (std::string item; v >> item;) {
        char* end = nullptr;
        const double x = std::strtod(item.c_str(), &end);
        if (end == item.c_str() || *end != '\0' || !std::isfinite(x))
          throw InputError(path + ": MetaImage " + key + " holds '" + item +
                           "', not a finite number");
        values.push_back(x);
      }
      if ((key == "TransformMatrix" || key == "Rotation" || key == "Orientation")) {
        if (values.size() != 9)
          throw InputError(path + ": MetaImage " + key + " needs 9 numbers for a volume, has " +
                           std::to_string(values.size()));
        const auto& m = values;
        const double det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
                           m[2] * (m[3] * m[7] - m[4] * m[6]);
        if (!(std::abs(det) > 1e-6)) throw InputError(path + ": MetaImage " + key + " is singular");
      }
      if (key == "ElementSpacing")
        for (double x : values)
          if (!(x != 0)) throw InputError(path + ": MetaImage ElementSpacing holds 0");
    } else if (key == "ElementNumberOfChannels") {
      v >> channels;
    } else if (key == "ElementDataFile") {
      data_file = value;
      found = true;
      break;
    }
  }
  if (!found)
    throw InputError(path + ": not a MetaImage header (no ElementDataFile line" +
                     std::string(header_end > kMaxHeader ? " in its first 64 KiB)" : ")"));
  while (ndims > 3 && static_cast<int>(dimsize.size()) >= ndims && dimsize[ndims - 1] == 1) --ndims;
  if (ndims != 3 || dimsize.size() < 3)
    throw InputError(path + ": MetaImage with NDims " + std::to_string(ndims) + " and " +
                     std::to_string(dimsize.size()) + " DimSize values; a volume needs 3");
  const Index3 dims{dimsize[0], dimsize[1], dimsize[2]};
  static const std::pair<const char*, ScalarType> kTypes[] = {
      {"MET_UCHAR", ScalarType::UInt8},   {"MET_CHAR", ScalarType::Int8},
      {"MET_USHORT", ScalarType::UInt16}, {"MET_SHORT", ScalarType::Int16},
      {"MET_UINT", ScalarType::UInt32},   {"MET_INT", ScalarType::Int32},
      {"MET_FLOAT", ScalarType::Float32}, {"MET_DOUBLE", ScalarType::Float64}};
  std::optional<ScalarType> type;
  for (const auto& [name, t] : kTypes)
    if (element_type == name) type = t;
  if (!type)
    throw InputError(path + ": MetaImage ElementType '" + element_type +
                     "' is not supported (MET_CHAR to MET_UINT, MET_FLOAT, MET_DOUBLE)");
  if (channels != 1)
    throw InputError(path + ": " + std::to_string(channels) +
                     " channels per sample; a volume needs one");
  const std::uint64_t bytes = checked_volume_bytes(*type, dims);
  ImageHeaderCheck out;
  const Endian endian = msb ? Endian::Big : Endian::Little;
  std::string file = path;
  std::uint64_t offset = header_end, available = size > header_end ? size - header_end : 0;
  if (data_file != "LOCAL") {
    if (data_file == "LIST" || data_file.find('%') != std::string::npos ||
        data_file.find(' ') != std::string::npos)
      throw InputError(path + ": MetaImage data in several files (ElementDataFile " + data_file +
                       ") is not supported");
    fs::path p = data_file;
    if (p.is_relative()) p = fs::path(path).parent_path() / p;
    file = p.string();
    const std::uint64_t n = file_size_of(file);
    if (header_size < -1)
      throw InputError(path + ": MetaImage HeaderSize " + std::to_string(header_size));
    offset =
        header_size == -1 ? (n >= bytes ? n - bytes : 0) : static_cast<std::uint64_t>(header_size);
    available = n > offset ? n - offset : 0;
  }
  if (compressed) {
    if (available * kMaxDeflateRatio < bytes)
      throw InputError(path + ": " + std::to_string(available) + " compressed bytes cannot hold " +
                       dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples");
    out.compressed = ImageHeaderCheck::Compressed{
        file, offset, bytes, false,
        dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples"};
    return out;
  }
  if (available < bytes)
    throw InputError(file + ": holds " + std::to_string(available) + " bytes of samples but " +
                     dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples need " +
                     std::to_string(bytes));
  if (available == bytes) out.plain = PlainData{file, offset, *type, dims, endian};
  return out;
}

void verify_compressed(const ImageHeaderCheck& check) {
  if (!check.compressed) return;
  const ImageHeaderCheck::Compressed& c = *check.compressed;
  std::ifstream f(c.file, std::ios::binary);
  if (!f) throw IoError("cannot open " + c.file + ": " + std::strerror(errno));
  f.seekg(static_cast<std::streamoff>(c.offset));
  z_stream z{};
  // 15 + 32: zlib or gzip, told apart by their headers (MetaIO writes zlib, NIfTI files are gzip).
  if (inflateInit2(&z, 15 + 32) != Z_OK) throw IoError(c.file + ": out of memory for zlib");
  std::vector<unsigned char> in(1 << 20), out(1 << 20);
  std::uint64_t total = 0;
  bool ended = false;
  int code = Z_OK;
  for (;;) {
    if (z.avail_in == 0) {
      f.read(reinterpret_cast<char*>(in.data()), static_cast<std::streamsize>(in.size()));
      z.next_in = in.data();
      z.avail_in = static_cast<uInt>(f.gcount());
      if (z.avail_in == 0) break;  // the file ends
    }
    z.next_out = out.data();
    z.avail_out = static_cast<uInt>(out.size());
    code = inflate(&z, Z_NO_FLUSH);
    total += out.size() - z.avail_out;
    if (code == Z_STREAM_END) {
      // gzip files may hold several members (as pigz writes); NIfTI's whole file is gzip.
      if (c.whole_gzip) {
        if (z.avail_in == 0 && f.peek() == std::ifstream::traits_type::eof()) {
          ended = true;
          break;
        }
        inflateReset(&z);
        continue;
      }
      ended = true;
      break;
    }
    if (code != Z_OK && code != Z_BUF_ERROR) break;
    if (!c.whole_gzip && total > c.need) break;
  }
  inflateEnd(&z);
  const std::string expected = std::to_string(c.need) + " bytes (" + c.what + ")";
  if (code == Z_DATA_ERROR || code == Z_NEED_DICT || code == Z_MEM_ERROR || code == Z_STREAM_ERROR)
    throw InputError(c.file + ": corrupt compressed data after " + std::to_string(total) +
                     " of the " + expected + " expected" +
                     (z.msg ? std::string(" (") + z.msg + ")" : ""));
  if (!c.whole_gzip && total > c.need)
    throw InputError(c.file + ": compressed data inflates to more than the " + expected +
                     " expected (too long)");
  if (!ended)
    throw InputError(c.file + ": compressed data cut off: it inflates to " + std::to_string(total) +
                     " bytes but " + expected + " were expected (truncated file)");
  if (total < c.need || (!c.whole_gzip && total != c.need))
    throw InputError(c.file + ": compressed data inflates to " + std::to_string(total) +
                     " bytes but " + expected + " were expected" +
                     (total < c.need ? " (too short)" : " (too long)"));
}

namespace {

// Bytes of a file read where asked, bounds checked against its size.
class FileBytes {
 public:
  explicit FileBytes(const std::string& path) : path_(path), f_(path, std::ios::binary) {
    if (!f_) throw IoError("cannot open " + path + ": " + std::strerror(errno));
    size_ = file_size_of(path);
  }
  std::uint64_t size() const { return size_; }
  bool fits(std::uint64_t at, std::uint64_t n) const { return at <= size_ && n <= size_ - at; }
  // n bytes at `at` (n small); false past the end.
  bool read(std::uint64_t at, void* out, std::size_t n) {
    if (!fits(at, n)) return false;
    f_.clear();
    f_.seekg(static_cast<std::streamoff>(at));
    f_.read(static_cast<char*>(out), static_cast<std::streamsize>(n));
    return static_cast<std::size_t>(f_.gcount()) == n;
  }

 private:
  std::string path_;
  std::ifstream f_;
  std::uint64_t size_ = 0;
};

std::string hex_tag(std::uint16_t group, std::uint16_t element) {
  char b[16];
  std::snprintf(b, sizeof b, "(%04X,%04X)", group, element);
  return b;
}

// The VR of the elements GDCM and ITK read through typed attributes (image geometry, pixel
// description, identification); nullptr for the others.
const char* expected_vr(std::uint16_t group, std::uint16_t element) {
  struct Known {
    std::uint16_t group, element;
    const char* vr;
  };
  static constexpr Known kKnown[] = {
      {0x0002, 0x0000, "UL"}, {0x0002, 0x0001, "OB"}, {0x0002, 0x0002, "UI"},
      {0x0002, 0x0003, "UI"}, {0x0002, 0x0010, "UI"}, {0x0002, 0x0012, "UI"},
      {0x0008, 0x0016, "UI"}, {0x0008, 0x0018, "UI"}, {0x0008, 0x0060, "CS"},
      {0x0018, 0x0050, "DS"}, {0x0018, 0x0088, "DS"}, {0x0020, 0x000D, "UI"},
      {0x0020, 0x000E, "UI"}, {0x0020, 0x0011, "IS"}, {0x0020, 0x0012, "IS"},
      {0x0020, 0x0013, "IS"}, {0x0020, 0x0032, "DS"}, {0x0020, 0x0037, "DS"},
      {0x0020, 0x1041, "DS"}, {0x0028, 0x0002, "US"}, {0x0028, 0x0004, "CS"},
      {0x0028, 0x0006, "US"}, {0x0028, 0x0008, "IS"}, {0x0028, 0x0010, "US"},
      {0x0028, 0x0011, "US"}, {0x0028, 0x0030, "DS"}, {0x0028, 0x0100, "US"},
      {0x0028, 0x0101, "US"}, {0x0028, 0x0102, "US"}, {0x0028, 0x0103, "US"},
      {0x0028, 0x1050, "DS"}, {0x0028, 0x1051, "DS"}, {0x0028, 0x1052, "DS"},
      {0x0028, 0x1053, "DS"}, {0x0028, 0x1054, "LO"}, {0x7FE0, 0x0010, "OB"}};
  for (const Known& k : kKnown)
    if (k.group == group && k.element == element) return k.vr;
  return nullptr;
}

struct DicomWalk {
  DicomWalk(FileBytes& f, const std::string& p) : file(f), path(p) {}
  FileBytes& file;
  const std::string& path;
  bool implicit = false, big = false;
  std::int64_t rows = -1, columns = -1, bits = -1, samples = 1, frames = 1;
  std::int64_t bits_stored = -1, high_bit = -1;
  bool pixel_found = false;
  std::uint64_t pixel_at = 0, pixel_length = 0;
  bool encapsulated = false;

  [[noreturn]] void cut(const std::string& what, std::uint64_t at, std::uint64_t need) const {
    throw InputError(path + ": DICOM " + what + " needs " + std::to_string(need) +
                     " bytes from offset " + std::to_string(at) + " but the file holds " +
                     std::to_string(file.size() > at ? file.size() - at : 0) +
                     " there (truncated file)");
  }
  std::uint16_t u16(const unsigned char* p) const { return get<std::uint16_t>(p, big); }
  std::uint32_t u32(const unsigned char* p) const { return get<std::uint32_t>(p, big); }

  // Elements from `at` until `end` (a defined length), or until the item delimiter when
  // `until_delimiter`. Returns the offset after the last element.
  std::uint64_t dataset(std::uint64_t at, std::uint64_t end, bool until_delimiter, int depth,
                        bool meta) {
    if (depth > 32) throw InputError(path + ": DICOM sequences nested more than 32 deep");
    while (until_delimiter || at < end) {
      unsigned char h[12];
      if (!file.read(at, h, 8)) {
        if (!until_delimiter && at >= file.size() && depth == 0) return at;
        cut("element header", at, 8);
      }
      const std::uint16_t group = u16(h), element = u16(h + 2);
      if (meta && group != 0x0002) return at;
      if (group == 0xFFFE) {
        if (element == 0xE00D && until_delimiter) return at + 8;
        throw InputError(path + ": malformed DICOM: delimiter " + hex_tag(group, element) +
                         " at offset " + std::to_string(at));
      }
      std::uint64_t length = 0, header = 8;
      char vr[3] = {0, 0, 0};
      if (implicit && !meta) {
        length = u32(h + 4);
      } else {
        vr[0] = static_cast<char>(h[4]);
        vr[1] = static_cast<char>(h[5]);
        // Only the standard's VRs: GDCM reads an element with another as implicit VR, taking
        // the VR's bytes for a length (hundreds of MB), or asserts on it in the meta group.
        static const char kVrs[] =
            "AEASATCSDADSDTFLFDISLOLTOBODOFOLOVOWPNSHSLSQSSSTSVTMUCUIULUNURUSUTUV";
        bool known = false;
        for (std::size_t i = 0; i + 1 < sizeof kVrs; i += 2)
          known = known || (kVrs[i] == vr[0] && kVrs[i + 1] == vr[1]);
        if (!known)
          throw InputError(path + ": malformed DICOM: element " + hex_tag(group, element) +
                           " at offset " + std::to_string(at) +
                           " has no valid value representation");
        // GDCM reads these through typed attributes and asserts when the VR is another.
        if (const char* want = expected_vr(group, element);
            want && !(want[0] == vr[0] && want[1] == vr[1]) &&
            !(group == 0x7FE0 && std::strcmp(vr, "OW") == 0))
          throw InputError(path + ": malformed DICOM: element " + hex_tag(group, element) +
                           " at offset " + std::to_string(at) + " has VR " + vr +
                           " where the standard says " + want);
        static const char* const kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                            "SV", "UC", "UN", "UR", "UT", "UV"};
        bool long_form = false;
        for (const char* l : kLong) long_form = long_form || std::strcmp(l, vr) == 0;
        if (long_form) {
          if (!file.read(at, h, 12)) cut("element header", at, 12);
          length = u32(h + 8);
          header = 12;
        } else {
          length = u16(h + 6);
        }
      }
      const std::uint64_t value = at + header;
      const bool pixel = group == 0x7FE0 && element == 0x0010 && depth == 0;
      if (length == 0xFFFFFFFFu) {
        if (pixel) {
          encapsulated = true;
          pixel_found = true;
          pixel_at = value;
        }
        at = sequence(value, depth + 1, pixel);
        continue;
      }
      if (!file.fits(value, length))
        cut(pixel ? "pixel data " + hex_tag(group, element) : "element " + hex_tag(group, element),
            value, length);
      if (pixel) {
        pixel_found = true;
        pixel_at = value;
        pixel_length = length;
      }
      if (std::strcmp(vr, "SQ") == 0 && length > 0)
        sequence_defined(value, value + length, depth + 1);
      if (depth == 0 && group == 0x0028 && length >= 2 && length <= 16) {
        unsigned char v[16];
        file.read(value, v, static_cast<std::size_t>(length));
        if (element == 0x0010) rows = u16(v);
        if (element == 0x0011) columns = u16(v);
        if (element == 0x0100) bits = u16(v);
        if (element == 0x0101) bits_stored = u16(v);
        if (element == 0x0102) high_bit = u16(v);
        if (element == 0x0002) samples = u16(v);
        if (element == 0x0008) {
          const std::string text(reinterpret_cast<char*>(v), static_cast<std::size_t>(length));
          frames = std::max<std::int64_t>(1, std::atoll(text.c_str()));
        }
      }
      if (meta && group == 0x0002 && element == 0x0000 && length == 4) {
        unsigned char v[4];
        file.read(value, v, 4);
        meta_length = true;
        meta_length_end = value + 4 + u32(v);
      }
      if (meta && group == 0x0002 && element == 0x0010 && length <= 64) {
        char ts[65] = {};
        file.read(value, ts, static_cast<std::size_t>(length));
        std::string uid(ts);
        while (!uid.empty() && (uid.back() == ' ' || uid.back() == '\0')) uid.pop_back();
        syntax = uid;
      }
      at = value + length;
    }
    return at;
  }

  // Items of a sequence of defined length.
  void sequence_defined(std::uint64_t at, std::uint64_t end, int depth) {
    while (at < end) {
      unsigned char h[8];
      if (!file.read(at, h, 8)) cut("sequence item", at, 8);
      const std::uint32_t length = u32(h + 4);
      if (u16(h) != 0xFFFE || u16(h + 2) != 0xE000)
        throw InputError(path + ": malformed DICOM sequence at offset " + std::to_string(at));
      if (length == 0xFFFFFFFFu) {
        at = dataset(at + 8, 0, true, depth, false);
      } else {
        if (!file.fits(at + 8, length)) cut("sequence item", at + 8, length);
        dataset(at + 8, at + 8 + length, false, depth, false);
        at += 8 + length;
      }
    }
  }

  // Items of a sequence of undefined length (or encapsulated pixel data's fragments), to its
  // delimiter; returns the offset after it.
  std::uint64_t sequence(std::uint64_t at, int depth, bool fragments) {
    for (;;) {
      unsigned char h[8];
      if (!file.read(at, h, 8)) cut(fragments ? "encapsulated pixel data" : "sequence item", at, 8);
      const std::uint16_t group = u16(h), element = u16(h + 2);
      const std::uint32_t length = u32(h + 4);
      if (group == 0xFFFE && element == 0xE0DD) return at + 8;
      if (group != 0xFFFE || element != 0xE000)
        throw InputError(path + ": malformed DICOM sequence at offset " + std::to_string(at));
      if (length == 0xFFFFFFFFu && !fragments) {
        at = dataset(at + 8, 0, true, depth, false);
        continue;
      }
      if (length == 0xFFFFFFFFu || !file.fits(at + 8, length))
        cut(fragments ? "pixel data fragment" : "sequence item", at + 8, length);
      if (!fragments) dataset(at + 8, at + 8 + length, false, depth, false);
      at += 8 + length;
    }
  }

  std::string syntax;
  bool meta_length = false;  // (0002,0000) present
  std::uint64_t meta_length_end = 0;
};

}  // namespace

void check_dicom_file(const std::string& path, bool given) {
  FileBytes file(path);
  unsigned char marker[4];
  if (!file.read(128, marker, 4) || std::memcmp(marker, "DICM", 4) != 0) {
    if (!given) return;  // other files in a series' directory: GDCM's scanner passes them by
    // A file given by name without the marker: GDCM would parse it as implicit VR from its first
    // byte, and size its allocations by whatever lengths it finds there.
    DicomWalk w{file, path};
    w.implicit = true;
    try {
      w.dataset(0, file.size(), false, 0, false);
    } catch (const InputError& e) {
      throw InputError(path +
                       ": not a DICOM file (no DICM marker, and not a readable implicit-VR "
                       "data set: " +
                       std::string(e.what()).substr(path.size() + 2) + ")");
    }
    return;
  }
  DicomWalk w{file, path};
  const std::uint64_t after_meta = w.dataset(132, file.size(), false, 0, true);
  // GDCM asserts on a file that ends with its meta group, or whose group length disagrees.
  if (w.meta_length && after_meta != w.meta_length_end)
    throw InputError(path + ": malformed DICOM: the file meta group length says it ends at byte " +
                     std::to_string(w.meta_length_end) + ", its elements end at " +
                     std::to_string(after_meta));
  if (after_meta >= file.size())
    throw InputError(path + ": DICOM file ends after its meta information (truncated file)");
  if (w.syntax == "1.2.840.10008.1.2.1.99") return;  // deflated: GDCM inflates and judges it
  w.implicit = w.syntax == "1.2.840.10008.1.2";
  w.big = w.syntax == "1.2.840.10008.1.2.2";
  w.dataset(after_meta, file.size(), false, 0, false);
  // GDCM asserts on pixel descriptions outside these.
  if (w.samples != 1 && w.samples != 3 && w.samples != 4)
    throw InputError(path + ": DICOM SamplesPerPixel is " + std::to_string(w.samples) +
                     " (1, 3 or 4)");
  if (w.bits_stored >= 0 && w.bits >= 0 &&
      (w.bits_stored > w.bits || (w.high_bit >= 0 && w.high_bit >= w.bits_stored)))
    throw InputError(path + ": DICOM BitsAllocated " + std::to_string(w.bits) + ", BitsStored " +
                     std::to_string(w.bits_stored) + " and HighBit " + std::to_string(w.high_bit) +
                     " do not fit one another");
  if (w.rows < 0 && w.columns < 0) return;  // no image (GDCM says what it is)
  if (!w.pixel_found)
    throw InputError(path + ": DICOM image of " + std::to_string(w.columns) + "x" +
                     std::to_string(w.rows) + " pixels has no pixel data (truncated file?)");
  if (w.encapsulated || w.rows <= 0 || w.columns <= 0 || w.bits <= 0) return;
  const std::uint64_t bits =
      static_cast<std::uint64_t>(w.rows) * static_cast<std::uint64_t>(w.columns) *
      static_cast<std::uint64_t>(std::max<std::int64_t>(w.samples, 1)) *
      static_cast<std::uint64_t>(w.frames) * static_cast<std::uint64_t>(w.bits);
  const std::uint64_t need = (bits + 7) / 8;
  if (w.pixel_length < need)
    throw InputError(path + ": DICOM pixel data holds " + std::to_string(w.pixel_length) +
                     " bytes but " + std::to_string(w.columns) + "x" + std::to_string(w.rows) +
                     " pixels x " + std::to_string(w.frames) + " frames of " +
                     std::to_string(w.bits) + " bits need " + std::to_string(need));
}

void check_dicom_input(const std::string& input) {
  std::error_code ec;
  const fs::path dir =
      fs::is_directory(input, ec) ? fs::path(input) : fs::path(input).parent_path();
  const bool file = !fs::is_directory(input, ec);
  if (file) check_dicom_file(input, true);
  for (const auto& e : fs::directory_iterator(dir.empty() ? fs::path(".") : dir, ec))
    if (e.is_regular_file(ec) && !(file && fs::equivalent(e.path(), input, ec)))
      check_dicom_file(e.path().string(), false);
}

void check_tiff_file(const std::string& path) {
  FileBytes file(path);
  unsigned char h[16];
  if (!file.read(0, h, 8))
    throw InputError(path + ": not a TIFF file (" + std::to_string(file.size()) + " bytes)");
  const bool little = h[0] == 'I' && h[1] == 'I';
  if (!little && !(h[0] == 'M' && h[1] == 'M'))
    throw InputError(path + ": not a TIFF file (no II or MM byte-order mark)");
  const bool swap = little != (std::endian::native == std::endian::little);
  const std::uint16_t version = get<std::uint16_t>(h + 2, swap);
  if (version != 42 && version != 43)
    throw InputError(path + ": not a TIFF file (version " + std::to_string(version) + ")");
  const bool big = version == 43;
  std::uint64_t ifd = 0;
  if (big) {
    if (!file.read(0, h, 16)) throw InputError(path + ": BigTIFF header truncated");
    ifd = get<std::uint64_t>(h + 8, swap);
  } else {
    ifd = get<std::uint32_t>(h + 4, swap);
  }
  const auto cut = [&](int page, const std::string& what, std::uint64_t at, std::uint64_t n) {
    throw InputError(path + ": TIFF page " + std::to_string(page) + ": " + what + " needs " +
                     std::to_string(n) + " bytes from offset " + std::to_string(at) +
                     " but the file holds " + std::to_string(file.size()) +
                     " bytes (truncated file)");
  };
  static const std::size_t kTypeSize[19] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4,
                                            8, 4, 8, 4, 0, 0, 8, 8, 8};
  std::vector<std::uint64_t> seen;
  std::array<std::uint64_t, 4> first{};       // page 1's width, height, bits and samples
  std::array<std::uint64_t, 3> first_kind{};  // its photometric, planar configuration, format
  int page = 0;
  while (ifd != 0) {
    ++page;
    if (std::find(seen.begin(), seen.end(), ifd) != seen.end() || page > 1000000)
      throw InputError(path + ": TIFF page directories form a loop");
    seen.push_back(ifd);
    const std::size_t count_size = big ? 8 : 2, entry_size = big ? 20 : 12,
                      inline_size = big ? 8 : 4;
    if (!file.read(ifd, h, count_size)) cut(page, "its directory", ifd, count_size);
    const std::uint64_t entries = big ? get<std::uint64_t>(h, swap) : get<std::uint16_t>(h, swap);
    if (!file.fits(ifd + count_size, entries * entry_size + inline_size))
      cut(page, "its directory", ifd, count_size + entries * entry_size + inline_size);
    std::uint64_t width = 0, height = 0, bps = 1, spp = 1, compression = 1, rows_per_strip = 0,
                  tile_w = 0, tile_h = 0, subfile = 0, photometric = 1, planar = 1, format = 1;
    std::vector<std::uint64_t> offsets, counts;
    for (std::uint64_t e = 0; e < entries; ++e) {
      unsigned char d[20];
      const std::uint64_t at = ifd + count_size + e * entry_size;
      file.read(at, d, entry_size);
      const std::uint16_t tag = get<std::uint16_t>(d, swap), type = get<std::uint16_t>(d + 2, swap);
      const std::uint64_t n =
          big ? get<std::uint64_t>(d + 4, swap) : get<std::uint32_t>(d + 4, swap);
      const std::size_t size = type < 19 ? kTypeSize[type] : 0;
      // ITK lists every custom tag through TIFFGetField with one pointer, where libtiff's
      // DotRange takes two: ITK then writes through a stray pointer (found by the fuzz replay).
      if (tag == 336)
        throw InputError(path + ": TIFF page " + std::to_string(page) +
                         " has a DotRange tag, which ITK's TIFF reader cannot read safely");
      if (size == 0) continue;  // unknown types are skipped by libtiff too
      if (n > (std::uint64_t{1} << 40) / size)
        throw InputError(path + ": TIFF page " + std::to_string(page) + ": tag " +
                         std::to_string(tag) + " claims " + std::to_string(n) + " values");
      const std::uint64_t bytes = n * size;
      std::uint64_t where = at + (big ? 12 : 8);
      if (bytes > inline_size) {
        where = big ? get<std::uint64_t>(d + 12, swap) : get<std::uint32_t>(d + 8, swap);
        if (!file.fits(where, bytes))
          cut(page, "tag " + std::to_string(tag) + "'s values", where, bytes);
      }
      const auto value = [&](std::uint64_t i) -> std::uint64_t {
        unsigned char v[8];
        file.read(where + i * size, v, size);
        if (size == 2) return get<std::uint16_t>(v, swap);
        if (size == 4) return get<std::uint32_t>(v, swap);
        if (size == 8) return get<std::uint64_t>(v, swap);
        return v[0];
      };
      if (n == 0) continue;
      switch (tag) {
        case 254:
          subfile |= value(0);
          break;
        case 255:  // the old SubfileType: 2 is a reduced-resolution image, as libtiff maps it
          if (value(0) == 2) subfile |= 1;
          break;
        case 262:
          photometric = value(0);
          break;
        case 284:
          planar = value(0);
          break;
        case 339:
          format = value(0);
          break;
        case 256:
          width = value(0);
          break;
        case 257:
          height = value(0);
          break;
        case 258:
          bps = value(0);
          break;
        case 259:
          compression = value(0);
          break;
        case 277:
          spp = value(0);
          break;
        case 278:
          rows_per_strip = value(0);
          break;
        case 322:
          tile_w = value(0);
          break;
        case 323:
          tile_h = value(0);
          break;
        case 273:
        case 324:
          if (n > (std::uint64_t{1} << 24))
            throw InputError(path + ": TIFF page " + std::to_string(page) + ": " +
                             std::to_string(n) + " strips");
          offsets.resize(n);
          for (std::uint64_t i = 0; i < n; ++i) offsets[i] = value(i);
          break;
        case 279:
        case 325:
          if (n > (std::uint64_t{1} << 24))
            throw InputError(path + ": TIFF page " + std::to_string(page) + ": " +
                             std::to_string(n) + " strips");
          counts.resize(n);
          for (std::uint64_t i = 0; i < n; ++i) counts[i] = value(i);
          break;
        default:
          break;
      }
    }
    if (offsets.size() != counts.size())
      throw InputError(path + ": TIFF page " + std::to_string(page) + " has " +
                       std::to_string(offsets.size()) + " strip offsets but " +
                       std::to_string(counts.size()) + " byte counts");
    std::uint64_t held = 0;
    for (std::size_t i = 0; i < offsets.size(); ++i) {
      if (!file.fits(offsets[i], counts[i]))
        cut(page, (tile_w ? "tile " : "strip ") + std::to_string(i), offsets[i], counts[i]);
      held += counts[i];
    }
    if (compression == 1 && width > 0 && height > 0 && width < (1u << 30) && height < (1u << 30) &&
        bps <= 64 && spp <= 64) {
      std::uint64_t need = 0;
      if (tile_w && tile_h) {
        const std::uint64_t across = (width + tile_w - 1) / tile_w,
                            down = (height + tile_h - 1) / tile_h;
        need = across * down * ((tile_w * spp * bps + 7) / 8) * tile_h;
      } else {
        const std::uint64_t rows =
            rows_per_strip && rows_per_strip < height ? rows_per_strip : height;
        const std::uint64_t row_bytes = (width * spp * bps + 7) / 8;
        // The last strip may be short.
        need = row_bytes * height;
        (void)rows;
      }
      if (held < need)
        throw InputError(path + ": TIFF page " + std::to_string(page) + " of " +
                         std::to_string(width) + "x" + std::to_string(height) + " " +
                         std::to_string(bps) + "-bit samples needs " + std::to_string(need) +
                         " bytes but its strips hold " + std::to_string(held));
    }
    // ITK sizes its buffer by the first page and reads every page into it: pages of another
    // size, or reduced-resolution and mask pages it counts differently, would overrun it.
    if (subfile & 5)
      throw InputError(path + ": TIFF page " + std::to_string(page) +
                       " is a reduced-resolution or mask image (NewSubfileType " +
                       std::to_string(subfile) + "); a volume is a stack of full pages");
    if (page == 1) {
      first = {width, height, bps, spp};
      first_kind = {photometric, planar, format};
    } else if (std::array<std::uint64_t, 3>{photometric, planar, format} != first_kind) {
      throw InputError(path + ": TIFF page " + std::to_string(page) +
                       " stores its samples differently from page 1 (photometric " +
                       std::to_string(photometric) + ", planar " + std::to_string(planar) +
                       ", sample format " + std::to_string(format) + " against " +
                       std::to_string(first_kind[0]) + ", " + std::to_string(first_kind[1]) + ", " +
                       std::to_string(first_kind[2]) + ")");
    } else if (std::array<std::uint64_t, 4>{width, height, bps, spp} != first) {
      throw InputError(path + ": TIFF page " + std::to_string(page) + " is " +
                       std::to_string(width) + "x" + std::to_string(height) + " with " +
                       std::to_string(spp) + " samples of " + std::to_string(bps) +
                       " bits where page 1 is " + std::to_string(first[0]) + "x" +
                       std::to_string(first[1]) + " with " + std::to_string(first[3]) +
                       " samples of " + std::to_string(first[2]) + " bits");
    }
    const std::uint64_t next_at = ifd + count_size + entries * entry_size;
    unsigned char nx[8];
    file.read(next_at, nx, inline_size);
    ifd = big ? get<std::uint64_t>(nx, swap) : get<std::uint32_t>(nx, swap);
  }
}

}  // namespace isotile
