// NRRD volumes through teem: attached or detached data, any encoding teem was built with.
#include <teem/nrrd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/volume/image_headers.h"
#include "core/volume/text_samples.h"
#include "core/volume/volume_io.h"

namespace isotile {

namespace {

// biff keeps its error messages in process-wide state with no locking.
std::mutex& teem_mutex() {
  static std::mutex m;
  return m;
}

struct NrrdNuker {
  void operator()(Nrrd* n) const { nrrdNuke(n); }
};

// teem's messages span several lines, one per call level; the CLI prints errors on one line.
std::string one_line(std::string text) {
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    if (c == '\n')
      out += "; ";
    else
      out += c;
  }
  return out;
}

std::string take_biff_error() {
  char* raw = biffGetDone(NRRD);
  if (!raw) return "unknown teem error";
  std::string text = raw;
  std::free(raw);
  return one_line(text);
}

std::optional<ScalarType> scalar_type_of_nrrd(int type) {
  switch (type) {
    case nrrdTypeChar:
      return ScalarType::Int8;
    case nrrdTypeUChar:
      return ScalarType::UInt8;
    case nrrdTypeShort:
      return ScalarType::Int16;
    case nrrdTypeUShort:
      return ScalarType::UInt16;
    case nrrdTypeInt:
      return ScalarType::Int32;
    case nrrdTypeUInt:
      return ScalarType::UInt32;
    case nrrdTypeFloat:
      return ScalarType::Float32;
    case nrrdTypeDouble:
      return ScalarType::Float64;
    default:
      return std::nullopt;
  }
}

double axis_spacing(const Nrrd& nrrd, const NrrdAxisInfo& axis) {
  if (std::isfinite(axis.spacing) && axis.spacing != 0) return axis.spacing;
  if (nrrd.spaceDim > 0) {
    double sum = 0;
    bool finite = true;
    for (unsigned d = 0; d < nrrd.spaceDim; ++d) {
      finite = finite && std::isfinite(axis.spaceDirection[d]);
      sum += axis.spaceDirection[d] * axis.spaceDirection[d];
    }
    if (finite && sum > 0) return std::sqrt(sum);
  }
  return 1;
}

Vec3d nrrd_origin(const Nrrd& nrrd) {
  Vec3d origin{0, 0, 0};
  if (nrrd.spaceDim == 0) return origin;
  for (unsigned d = 0; d < nrrd.spaceDim; ++d)
    if (!std::isfinite(nrrd.spaceOrigin[d])) return origin;
  for (unsigned d = 0; d < nrrd.spaceDim && d < 3; ++d) origin[d] = nrrd.spaceOrigin[d];
  return origin;
}

// The world frame of a NRRD with a 3D space: its space directions (unit columns) and space
// origin, turned into LPS when the space is a RAS or LAS one (as ITK's NRRD reader does).
std::optional<WorldFrame> nrrd_world(const Nrrd& nrrd, unsigned first) {
  if (nrrd.spaceDim != 3) return std::nullopt;
  WorldFrame w;
  for (int a = 0; a < 3; ++a) {
    const NrrdAxisInfo& axis = nrrd.axis[first + a];
    double len = 0;
    for (int r = 0; r < 3; ++r) {
      if (!std::isfinite(axis.spaceDirection[r])) return std::nullopt;
      len += axis.spaceDirection[r] * axis.spaceDirection[r];
    }
    len = std::sqrt(len);
    if (len == 0) return std::nullopt;
    for (int r = 0; r < 3; ++r) w.direction[3 * r + a] = axis.spaceDirection[r] / len;
  }
  w.origin = nrrd_origin(nrrd);
  Vec3d sign{1, 1, 1};
  if (nrrd.space == nrrdSpaceRightAnteriorSuperior ||
      nrrd.space == nrrdSpaceRightAnteriorSuperiorTime)
    sign = {-1, -1, 1};
  else if (nrrd.space == nrrdSpaceLeftAnteriorSuperior ||
           nrrd.space == nrrdSpaceLeftAnteriorSuperiorTime)
    sign = {1, -1, 1};
  for (int r = 0; r < 3; ++r) {
    w.origin[r] *= sign[r];
    for (int c = 0; c < 3; ++c) w.direction[3 * r + c] *= sign[r];
  }
  return w;
}

}  // namespace

namespace {

void probe_file(const std::string& path) {
  // teem's own message for a missing file is buried in a chain of call levels.
  if (std::FILE* probe = std::fopen(path.c_str(), "rb"))
    std::fclose(probe);
  else
    throw IoError("cannot open " + path + ": " + std::strerror(errno));
}

struct HeaderInfo {
  ScalarType type;
  Index3 dims;
  Vec3d spacing;
  Vec3d origin;
  std::optional<WorldFrame> world;
};

HeaderInfo header_info(const std::string& path, const Nrrd& nrrd) {
  unsigned first = 0;
  if (nrrd.dim == 4 && nrrd.axis[0].size == 1)
    first = 1;
  else if (nrrd.dim != 3 && !(nrrd.dim == 4 && nrrd.axis[3].size == 1))
    throw InputError(path + ": NRRD has " + std::to_string(nrrd.dim) +
                     " axes; a volume needs 3 (or 4 with the first or the last of size 1)");
  // An axis of colour, vector, tensor or list kind holds a sample's components, not positions:
  // read as x (the fastest axis, where NRRD puts them) it made a "volume" of interleaved
  // channels. Domain kinds (space, time, domain) and none are taken as positions.
  for (unsigned a = first; a < first + 3; ++a) {
    const int kind = nrrd.axis[a].kind;
    if (kind != nrrdKindUnknown && !nrrdKindIsDomain(kind))
      throw InputError(path + ": NRRD axis " + std::to_string(a + 1) + " of " +
                       std::to_string(nrrd.dim) + " is of kind '" + airEnumStr(nrrdKind, kind) +
                       "' (" + std::to_string(nrrd.axis[a].size) +
                       " components of a sample, not positions); a volume needs three axes of "
                       "space or domain kind with one scalar per sample");
  }
  const std::optional<ScalarType> type = scalar_type_of_nrrd(nrrd.type);
  if (!type)
    throw InputError(path + ": NRRD sample type '" + airEnumStr(nrrdType, nrrd.type) +
                     "' is not supported (int8 to uint32, float or double)");
  // In a NRRD with a space, each axis's space direction is its step in that space: a vector of
  // no length (0, 1e-300, or `none`) gives it none, and the made-up spacing of 1 and identity
  // directions that followed put the mesh elsewhere, rotated, with exit 0.
  if (nrrd.spaceDim > 0)
    for (unsigned a = first; a < first + 3; ++a) {
      const NrrdAxisInfo& axis = nrrd.axis[a];
      double sum = 0;
      bool finite = true;
      for (unsigned d = 0; d < nrrd.spaceDim; ++d) {
        finite = finite && std::isfinite(axis.spaceDirection[d]);
        sum += axis.spaceDirection[d] * axis.spaceDirection[d];
      }
      if (!finite || !(sum > 0) || !std::isfinite(sum))
        throw InputError(path + ": NRRD axis " + std::to_string(a + 1) + " of " +
                         std::to_string(nrrd.dim) + " has " +
                         (finite ? "a space direction of no length" : "no space direction") +
                         " (`space directions`), so the samples along it are no distance "
                         "apart; give each of the volume's axes a vector");
    }
  HeaderInfo h{*type, {}, {}, nrrd_origin(nrrd), nrrd_world(nrrd, first)};
  for (int a = 0; a < 3; ++a) {
    const NrrdAxisInfo& axis = nrrd.axis[first + a];
    h.dims[a] = static_cast<std::int64_t>(axis.size);
    h.spacing[a] = axis_spacing(nrrd, axis);
  }
  return h;
}

struct IoStateNixer {
  void operator()(NrrdIoState* nio) const {
    if (nio->dataFile) std::fclose(nio->dataFile);
    nio->dataFile = nullptr;
    nrrdIoStateNix(nio);
  }
};

std::uint64_t after_lines(const std::string& file, std::uint64_t lines);

// The file holding a NRRD's data (one detached file, or the header's own) and where its bytes
// begin in it: 0 for a detached file, before any line or byte skip; in the header's own file
// where teem stopped reading, after the header and its line and byte skips. Nothing when teem
// did not keep the attached file open.
struct DataStart {
  std::string file;
  std::uint64_t offset = 0;
};
std::optional<DataStart> data_start(const std::string& path, const NrrdIoState& nio) {
  if (nio.dataFNArr->len == 1) {
    std::filesystem::path data = nio.dataFN[0];
    if (data.is_relative()) data = std::filesystem::path(path).parent_path() / data;
    return DataStart{data.string(), 0};
  }
  // Attached: the samples follow the header in the same file.
  if (!nio.dataFile) return std::nullopt;
  const long at = std::ftell(nio.dataFile);
  if (at < 0) return std::nullopt;
  return DataStart{path, static_cast<std::uint64_t>(at)};
}

// A NRRD's header alone, the file holding its data kept open where that is the header's own
// (data_start() asks it where the samples begin).
struct NrrdHeader {
  std::unique_ptr<Nrrd, NrrdNuker> nrrd;
  std::unique_ptr<NrrdIoState, IoStateNixer> nio;
};
NrrdHeader load_header(const std::string& path) {
  NrrdHeader h{std::unique_ptr<Nrrd, NrrdNuker>(nrrdNew()),
               std::unique_ptr<NrrdIoState, IoStateNixer>(nrrdIoStateNew())};
  h.nio->skipData = AIR_TRUE;
  h.nio->keepNrrdDataFileOpen = AIR_TRUE;
  std::lock_guard lock(teem_mutex());
  if (nrrdLoad(h.nrrd.get(), path.c_str(), h.nio.get()) != 0)
    throw InputError(path + ": not a readable NRRD file: " + take_biff_error());
  return h;
}

// Where a gzip-encoded NRRD's stream lies (the data file and its offset), for
// verify_compressed: teem takes a stream cut short as the end of the data and leaves the rest of
// the samples as they were. Nothing for other encodings and several data files.
std::optional<ImageHeaderCheck::Compressed> gzip_stream(const std::string& path,
                                                        const NrrdHeader& header) {
  const auto& [nrrd, nio] = header;
  if (nio->encoding != nrrdEncodingGzip || nio->dataFNArr->len > 1 || nio->byteSkip != 0)
    return std::nullopt;
  // Lines skipped before a detached file's compressed data (teem skips them as text). In the
  // header's own file, teem has read past them already (data_start()).
  std::uint64_t lines = 0;
  if (nio->lineSkip > 0 && nio->dataFNArr->len == 1) lines = nio->lineSkip;
  const HeaderInfo h = header_info(path, *nrrd);
  ImageHeaderCheck::Compressed c;
  c.need = checked_volume_bytes(h.type, h.dims);
  c.what = std::to_string(h.dims[0]) + "x" + std::to_string(h.dims[1]) + "x" +
           std::to_string(h.dims[2]) + " " + std::string(scalar_name(h.type)) + " samples";
  const std::optional<DataStart> start = data_start(path, *nio);
  if (!start) return std::nullopt;
  c.file = start->file;
  c.offset = start->offset;
  c.members = true;  // teem reads a gzip stream of several members, as gzip(1) does
  if (lines > 0) c.offset = after_lines(c.file, lines);
  return c;
}

// Where a detached data file's samples start after `lines` lines (teem skips them as text).
std::uint64_t after_lines(const std::string& file, std::uint64_t lines) {
  std::ifstream f(file, std::ios::binary);
  std::string line;
  for (std::uint64_t i = 0; i < lines; ++i)
    if (!std::getline(f, line))
      throw InputError(file + ": the NRRD header's line skip of " + std::to_string(lines) +
                       " lines passes the data file's end");
  return static_cast<std::uint64_t>(f.tellg());
}

// Where an ascii-encoded NRRD's text lies, for verify_text_samples: teem casts each token
// through an int (300 in a uchar file read 44) and stops at the first character that is not a
// digit (1e2 read 1). One piece per data file: teem reads an equal share of the samples from
// each, after its line skip and then its byte skip (in the header's own file, teem has read past
// them already: data_start()). Nothing for other encodings.
std::vector<TextSamples> ascii_text(const std::string& path, const NrrdHeader& header) {
  const auto& [nrrd, nio] = header;
  if (nio->encoding != nrrdEncodingAscii || nio->byteSkip < 0) return {};
  const HeaderInfo h = header_info(path, *nrrd);
  const std::int64_t count = h.dims[0] * h.dims[1] * h.dims[2];
  const unsigned files = nio->dataFNArr->len;
  TextSamples t;
  t.type = h.type;
  t.commas = true;
  t.what = "NRRD ascii";
  if (files <= 1) {
    const std::optional<DataStart> start = data_start(path, *nio);
    if (!start) return {};
    t.file = start->file;
    t.offset = start->offset;
    if (files == 1)
      t.offset = after_lines(t.file, nio->lineSkip) + static_cast<std::uint64_t>(nio->byteSkip);
    t.count = count;
    return {t};
  }
  std::vector<TextSamples> pieces;
  t.count = count / files;
  for (unsigned k = 0; k < files; ++k) {
    std::filesystem::path data = nio->dataFN[k];
    if (data.is_relative()) data = std::filesystem::path(path).parent_path() / data;
    t.file = data.string();
    t.offset = after_lines(t.file, nio->lineSkip) + static_cast<std::uint64_t>(nio->byteSkip);
    t.first = k * t.count;
    pieces.push_back(t);
  }
  return pieces;
}

// nrrd_data_layout() from a loaded header.
std::optional<NrrdDataLayout> data_layout(const std::string& path, const NrrdHeader& header) {
  const auto& [nrrd, nio] = header;
  const HeaderInfo h = header_info(path, *nrrd);
  NrrdDataLayout out;
  out.type = h.type;
  out.dims = h.dims;
  out.spacing = h.spacing;
  out.origin = h.origin;
  out.world = h.world;
  out.endian = nio->endian == airEndianBig ? Endian::Big : Endian::Little;
  if (nio->lineSkip != 0 || nio->dataFNArr->len > 1) return std::nullopt;
  if (nio->encoding == nrrdEncodingGzip)
    out.gzip = true;
  else if (nio->encoding != nrrdEncodingRaw)
    return std::nullopt;
  const std::uint64_t bytes = checked_volume_bytes(h.type, h.dims);
  const std::optional<DataStart> data = data_start(path, *nio);
  if (!data) return std::nullopt;
  out.data_file = data->file;
  // Where the samples begin: a detached file's skip is counted here, the header's own file's
  // was passed by teem already (data_start()).
  const bool attached = nio->dataFNArr->len == 0;
  const std::uint64_t start = data->offset;
  if (out.gzip) {
    // The gzip stream starts where the header ends (attached) or at the data file's start; a
    // byte skip counts within the decompressed data, which cannot be streamed from an offset.
    if (nio->byteSkip != 0 || (!attached && start != 0)) return std::nullopt;
    out.offset = start;
    return out;
  }
  if (nio->byteSkip == -1) {
    // The samples are the file's last bytes.
    std::error_code ec;
    const std::uintmax_t size = std::filesystem::file_size(out.data_file, ec);
    if (ec || size < bytes) return std::nullopt;
    out.offset = size - bytes;
  } else {
    out.offset = attached ? start : start + static_cast<std::uint64_t>(nio->byteSkip);
  }
  return out;
}

}  // namespace

Volume read_nrrd(const std::string& path) {
  probe_file(path);
  const NrrdHeader header = load_header(path);  // for the checks before and after teem's read
  if (std::optional<ImageHeaderCheck::Compressed> gz = gzip_stream(path, header)) {
    ImageHeaderCheck check;
    check.compressed = std::move(gz);
    verify_compressed(check);
  }
  // Raw data must be exactly the samples, as out of core (teem reads a longer file with a warning
  // on stderr).
  if (const std::optional<NrrdDataLayout> d = data_layout(path, header); d && !d->gzip) {
    std::error_code ec;
    const std::uintmax_t size = std::filesystem::file_size(d->data_file, ec);
    if (!ec) check_plain_size(d->data_file, size, d->offset, d->type, d->dims);
  }

  std::unique_ptr<Nrrd, NrrdNuker> nrrd(nrrdNew());
  {
    std::lock_guard lock(teem_mutex());
    if (nrrdLoad(nrrd.get(), path.c_str(), nullptr) != 0)
      throw InputError(path + ": not a readable NRRD file: " + take_biff_error());
  }
  const HeaderInfo h = header_info(path, *nrrd);
  Volume volume(h.type, h.dims, h.spacing, h.origin);
  volume.set_world(h.world);
  const std::size_t have = nrrdElementNumber(nrrd.get()) * nrrdElementSize(nrrd.get());
  if (have != volume.byte_size() || nrrd->data == nullptr)
    throw InputError(path + ": NRRD holds " + std::to_string(have) + " bytes of data, expected " +
                     std::to_string(volume.byte_size()));
  std::memcpy(volume.bytes(), nrrd->data, volume.byte_size());
  nrrd.reset();
  for (const TextSamples& text : ascii_text(path, header))
    verify_text_samples(text, volume.bytes(), volume.dims());
  check_finite(volume.view(), path);
  return volume;
}

std::optional<NrrdDataLayout> nrrd_data_layout(const std::string& path) {
  probe_file(path);
  return data_layout(path, load_header(path));
}

}  // namespace isotile
