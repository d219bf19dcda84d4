// NIfTI-1/2 and MetaImage headers, read and checked without ITK.
#include "core/volume/image_headers.h"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/volume/file_bytes.h"

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

using file_check::get;

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

}  // namespace

ImageHeaderCheck check_nifti_header(const std::string& path) {
  const bool gz = ends_with_ci(path, ".gz");
  // ITK's nifti library takes .nii and .nii.gz in lower or upper case only: a mixed-case name
  // failed with three lines of its own and "not a readable Nifti file".
  {
    const std::size_t n = gz ? 7 : 4;
    const std::string ext = path.size() >= n ? path.substr(path.size() - n) : path;
    const bool lower =
        std::none_of(ext.begin(), ext.end(), [](unsigned char c) { return std::isupper(c); });
    const bool upper =
        std::none_of(ext.begin(), ext.end(), [](unsigned char c) { return std::islower(c); });
    if (!lower && !upper)
      throw InputError(path +
                       ": ITK's NIfTI reader takes the extension in lower or upper case "
                       "only (.nii, .NII, .nii.gz, .NII.GZ), not '" +
                       ext + "'; rename the file");
  }
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
  // ITK 5.2's NIfTI reader (niftilib's NIfTI-1 code) refuses NIfTI-2 saying only "not a readable
  // Nifti file". (The checks below read both versions' fields, for a reader that takes both.)
  if (version == 2)
    throw InputError(path +
                     ": a NIfTI-2 file, which ITK 5.2's NIfTI reader cannot read; save it as "
                     "NIfTI-1 (e.g. with nibabel), NRRD or MetaImage");
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
  if (version == 1) {
    // NIfTI-1 spatial units (xyzt_units' low 3 bits): 1 metre, 2 millimetre, 3 micron; ITK
    // reads the spacing in millimetres.
    const int units = h[123] & 7;
    out.origin_scale = units == 1 ? 1e3 : units == 3 ? 1e-3 : 1;
    // pixdim 0 is no spacing; niftilib makes it 1 unless the sform gives the voxel's size.
    const int sform = get<std::int16_t>(h.data() + 254, swap);
    static const char* const kAxis[3] = {"x", "y", "z"};
    for (int a = 1; a <= 3 && sform <= 0; ++a)
      if (dims[a - 1] > 1 && get<float>(h.data() + 76 + 4 * a, swap) == 0) {
        out.unknown_spacing = path + ": NIfTI pixdim[" + std::to_string(a) +
                              "] (the spacing along " + kAxis[a - 1] +
                              ") is 0 and no sform gives it, so the distance between samples is "
                              "unknown (ITK's reader would take 1); give the spacing with "
                              "--spacing X,Y,Z";
        break;
      }
  }
  if (gz) {
    out.compressed = ImageHeaderCheck::Compressed{
        path, 0, offset + bytes, true,
        dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples after " +
            std::to_string(offset) + " header bytes"};
    if (is_floating(*type))
      out.compressed->floats = ImageHeaderCheck::Floats{*type, dims, offset, swap};
  }
  // A slope of 0 (or not a number) means no scaling in NIfTI, intercept included; ITK 5.2 takes it
  // for 1 and adds the intercept, shifting every sample. Such a file would read wrong through it.
  if ((slope == 0 || !std::isfinite(slope)) && std::isfinite(inter) && inter != 0)
    throw InputError(path + ": NIfTI scl_slope " + (std::ostringstream() << slope).str() +
                     " with scl_inter " + (std::ostringstream() << inter).str() +
                     ": NIfTI reads the samples unscaled, ITK's reader would add the intercept; "
                     "set scl_inter to 0 (or scl_slope to 1, if the intercept is meant)");
  if (std::isfinite(slope) && slope != 0 && (slope != 1 || (std::isfinite(inter) && inter != 0))) {
    out.rescaled = true;
    out.rescale_slope = slope;
    out.rescale_intercept = std::isfinite(inter) ? inter : 0;
  }
  // Rescaled floating-point samples go through ITK, whose nifti library turns NaN and Inf into 0:
  // checked in the file first (verify_plain_floats).
  if (!gz && out.rescaled && is_floating(*type))
    out.plain_floats =
        ImageHeaderCheck::PlainFloats{path, ImageHeaderCheck::Floats{*type, dims, offset, swap}};
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
  bool compressed = false, msb = false, found = false, text = false;
  std::int64_t header_size = 0, channels = 1;
  std::optional<std::uint64_t> compressed_size;
  std::uint64_t header_end = 0;
  // Per-axis fields and their counts: MetaIO needs NDims values in each and, given fewer, fails
  // with five lines on stderr that name DimSize.
  std::vector<std::pair<std::string, std::size_t>> per_axis;
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
    } else if (key == "BinaryData") {
      text = value == "False" || value == "false";
    } else if (key == "CompressedData") {
      compressed = value == "True" || value == "true";
    } else if (key == "CompressedDataSize") {
      if (value.empty() || value.size() > 18 ||
          value.find_first_not_of("0123456789") != std::string::npos)
        throw InputError(path + ": MetaImage CompressedDataSize is '" + value +
                         "', not a byte count");
      compressed_size = std::stoull(value);
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
      if (key != "TransformMatrix" && key != "Rotation" && key != "Orientation")
        per_axis.emplace_back(key, values.size());
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
  for (const auto& [key, count] : per_axis)
    if (ndims > 0 && count < static_cast<std::size_t>(ndims))
      throw InputError(path + ": MetaImage " + key + " has " + std::to_string(count) +
                       (count == 1 ? " value" : " values") + " where NDims " +
                       std::to_string(ndims) + " needs " + std::to_string(ndims));
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
  // MetaIO takes these three spellings for data in the header's own file.
  const bool local = data_file == "LOCAL" || data_file == "Local" || data_file == "local";
  if (!local) {
    // MetaIO reads a name with `%` as a pattern ("slice%03d.raw 1 40 1") and LIST as a list;
    // any other value, spaces and all, is one file's name.
    if (data_file == "LIST" || data_file.find('%') != std::string::npos)
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
    // MetaIO inflates CompressedDataSize bytes from the samples' start; without the field it
    // takes the whole file from its first byte, which for data after the header is the header's
    // text: it prints "Uncompress failed" and returns a buffer it never filled.
    if (local && !compressed_size)
      throw InputError(path +
                       ": compressed MetaImage data in the header's own file needs "
                       "CompressedDataSize (the size of the compressed samples), which "
                       "the header lacks");
    if (compressed_size && *compressed_size > available)
      throw InputError(file + ": CompressedDataSize is " + std::to_string(*compressed_size) +
                       " bytes but the file holds " + std::to_string(available) +
                       " after the header (truncated file)");
    if (compressed_size) available = *compressed_size;
    if (available * kMaxDeflateRatio < bytes)
      throw InputError(path + ": " + std::to_string(available) + " compressed bytes cannot hold " +
                       dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples");
    out.compressed = ImageHeaderCheck::Compressed{
        file, offset, bytes, false,
        dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples"};
    out.compressed->limit = compressed_size.value_or(0);
    return out;
  }
  if (text && !compressed) {
    // Samples as text (BinaryData = False): MetaIO reads each as a double and casts it to the
    // type, so 300 in a MET_UCHAR file read 44; checked after ITK's read (verify_text_samples).
    out.text =
        TextSamples{file, offset, *type, dims[0] * dims[1] * dims[2], false, "MetaImage text"};
    return out;
  }
  if (available < bytes)
    throw InputError(file + ": holds " + std::to_string(available) + " bytes of samples but " +
                     dims_text(dims) + " " + std::string(scalar_name(*type)) + " samples need " +
                     std::to_string(bytes));
  if (available == bytes) out.plain = PlainData{file, offset, *type, dims, endian};
  return out;
}

namespace {

// NIfTI's floating-point samples checked for NaN and Inf as their bytes go by, in pieces of any
// size (an inflate buffer, a read), a sample split between two pieces included.
class FloatScan {
 public:
  explicit FloatScan(const ImageHeaderCheck::Floats& f)
      : f_(f),
        size_(scalar_size(f.type)),
        end_(f.at + size_ * static_cast<std::uint64_t>(f.dims[0] * f.dims[1] * f.dims[2])) {}

  // The `n` bytes at offset `from` of the stream the samples lie in.
  void feed(const unsigned char* bytes, std::uint64_t from, std::size_t n) {
    const std::uint64_t lo = std::max(from, f_.at), hi = std::min(from + n, end_);
    std::uint64_t p = lo;
    // Whole samples straight from the piece while none is pending (the usual case).
    if (partial_size_ == 0 && !f_.swap && size_ == 4)
      for (; p + 4 <= hi; p += 4) {
        float v;
        std::memcpy(&v, bytes + (p - from), 4);
        count(std::isfinite(v));
      }
    for (; p < hi; ++p) {
      partial_[partial_size_++] = bytes[p - from];
      if (partial_size_ < size_) continue;
      partial_size_ = 0;
      if (f_.swap) std::reverse(partial_, partial_ + size_);
      if (size_ == 4) {
        float v;
        std::memcpy(&v, partial_, 4);
        count(std::isfinite(v));
      } else {
        double v;
        std::memcpy(&v, partial_, 8);
        count(std::isfinite(v));
      }
    }
  }

  // Throws InputError naming `file`, as check_finite names a volume's, where one was not finite.
  void check(const std::string& file) const {
    if (non_finite_ == 0) return;
    const Index3& d = f_.dims;
    throw InputError(faulty_samples(file, non_finite_, "NaN or Inf",
                                    {first_ % d[0], first_ / d[0] % d[1], first_ / d[0] / d[1]}) +
                     "; isosurfaces need finite values");
  }

 private:
  void count(bool finite) {
    if (!finite && non_finite_++ == 0) first_ = index_;
    ++index_;
  }

  ImageHeaderCheck::Floats f_;
  std::size_t size_;
  std::uint64_t end_;
  unsigned char partial_[8];
  std::size_t partial_size_ = 0;
  std::int64_t non_finite_ = 0, first_ = -1, index_ = 0;
};

}  // namespace

void verify_plain_floats(const ImageHeaderCheck& check) {
  if (!check.plain_floats) return;
  const ImageHeaderCheck::PlainFloats& p = *check.plain_floats;
  std::ifstream f(p.file, std::ios::binary);
  if (!f) throw IoError("cannot open " + p.file + ": " + std::strerror(errno));
  FloatScan scan(p.floats);
  std::vector<unsigned char> buffer(1 << 20);
  for (std::uint64_t at = 0;;) {
    f.read(reinterpret_cast<char*>(buffer.data()), static_cast<std::streamsize>(buffer.size()));
    const auto got = static_cast<std::size_t>(f.gcount());
    if (got == 0) break;
    scan.feed(buffer.data(), at, got);
    at += got;
  }
  scan.check(p.file);
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
  std::uint64_t total = 0, left = c.limit ? c.limit : UINT64_MAX;  // compressed bytes to read
  std::optional<FloatScan> floats;
  if (c.floats) floats.emplace(*c.floats);
  bool ended = false;
  int code = Z_OK;
  // After a gzip member: whether another follows, i.e. the next two bytes are gzip's magic. Other
  // bytes end the stream unread, as zlib's gz* reads (and gzip -d, with a warning) take them: the
  // raw .gz reader, every reader out of core and teem read them so, and an in-core check that
  // refused them would refuse a file the same run accepts with --memory. The sample count still
  // catches a member lost in them (too short) or one more volume (too long).
  const auto next_member = [&] {
    unsigned char next[2];
    std::size_t have = std::min<std::size_t>(z.avail_in, 2);
    if (have > 0) std::memcpy(next, z.next_in, have);
    if (have < 2 && left > 0) {
      const auto at = f.tellg();
      f.read(reinterpret_cast<char*>(next + have),
             static_cast<std::streamsize>(std::min<std::uint64_t>(2 - have, left)));
      have += static_cast<std::size_t>(f.gcount());
      f.clear();
      f.seekg(at);
    }
    return have == 2 && next[0] == 0x1f && next[1] == 0x8b;
  };
  for (;;) {
    if (z.avail_in == 0) {
      f.read(reinterpret_cast<char*>(in.data()),
             static_cast<std::streamsize>(std::min<std::uint64_t>(in.size(), left)));
      z.next_in = in.data();
      z.avail_in = static_cast<uInt>(f.gcount());
      left -= z.avail_in;
      if (z.avail_in == 0) break;  // the file, or the header's compressed bytes, end
    }
    z.next_out = out.data();
    z.avail_out = static_cast<uInt>(out.size());
    code = inflate(&z, Z_NO_FLUSH);
    if (floats) floats->feed(out.data(), total, out.size() - z.avail_out);
    total += out.size() - z.avail_out;
    if (code == Z_STREAM_END) {
      // gzip files may hold several members (as pigz writes); NIfTI's whole file is gzip, and
      // so is NRRD's data.
      if (c.whole_gzip || c.members) {
        if (!next_member()) {
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
  if (!ended && total >= c.need)
    throw InputError(c.file + ": compressed data cut off: all " + expected +
                     " are there but the stream's end is cut off (truncated file)");
  if (!ended)
    throw InputError(c.file + ": compressed data cut off: it inflates to " + std::to_string(total) +
                     " bytes but " + expected + " were expected (truncated file)");
  if (total < c.need || (!c.whole_gzip && total != c.need))
    throw InputError(c.file + ": compressed data inflates to " + std::to_string(total) +
                     " bytes but " + expected + " were expected" +
                     (total < c.need ? " (too short)" : " (too long)"));
  if (floats) floats->check(c.file);
}

}  // namespace isotile
