// NRRD volumes through teem: attached or detached data, any encoding teem was built with.
#include <teem/nrrd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/volume_io.h"

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

}  // namespace

Volume read_nrrd(const std::string& path) {
  // teem's own message for a missing file is buried in a chain of call levels.
  if (std::FILE* probe = std::fopen(path.c_str(), "rb"))
    std::fclose(probe);
  else
    throw IoError("cannot open " + path + ": " + std::strerror(errno));

  std::unique_ptr<Nrrd, NrrdNuker> nrrd(nrrdNew());
  {
    std::lock_guard lock(teem_mutex());
    if (nrrdLoad(nrrd.get(), path.c_str(), nullptr) != 0)
      throw InputError(path + ": not a readable NRRD file: " + take_biff_error());
  }

  unsigned first = 0;
  if (nrrd->dim == 4 && nrrd->axis[0].size == 1)
    first = 1;
  else if (nrrd->dim != 3)
    throw InputError(path + ": NRRD has " + std::to_string(nrrd->dim) +
                     " axes; a volume needs 3 (or 4 with the first of size 1)");

  const std::optional<ScalarType> type = scalar_type_of_nrrd(nrrd->type);
  if (!type)
    throw InputError(path + ": NRRD sample type '" + airEnumStr(nrrdType, nrrd->type) +
                     "' is not supported (int8 to uint32, float or double)");

  Index3 dims{};
  Vec3d spacing{};
  for (int a = 0; a < 3; ++a) {
    const NrrdAxisInfo& axis = nrrd->axis[first + a];
    dims[a] = static_cast<std::int64_t>(axis.size);
    spacing[a] = axis_spacing(*nrrd, axis);
  }
  Volume volume(*type, dims, spacing, nrrd_origin(*nrrd));
  const std::size_t have = nrrdElementNumber(nrrd.get()) * nrrdElementSize(nrrd.get());
  if (have != volume.byte_size() || nrrd->data == nullptr)
    throw InputError(path + ": NRRD holds " + std::to_string(have) + " bytes of data, expected " +
                     std::to_string(volume.byte_size()));
  std::memcpy(volume.bytes(), nrrd->data, volume.byte_size());
  nrrd.reset();
  check_finite(volume.view(), path);
  return volume;
}

}  // namespace isotile
