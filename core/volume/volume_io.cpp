// Dispatch on the input's name, and the checks every reader shares.
#include "core/volume/volume_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <type_traits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "core/errors.h"
#include "core/volume/procedural_fields.h"

namespace isotile {

namespace {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

// Options that only a raw file can use would otherwise be dropped without a word.
void reject_raw_only_options(const std::string& input, const RawOptions& raw, const char* kind) {
  if (raw.dims || raw.type || raw.endian == Endian::Big)
    throw InputError(input + ": --dims, --type and big-endian apply only to raw files; a " + kind +
                     " says its own");
}

struct NonFinite {
  std::int64_t count = 0;
  // Position of the first one in x-fastest order, as a linear index into the view; -1 if none.
  std::int64_t first = -1;
};

template <class T>
NonFinite count_non_finite(const VolumeView& view) {
  const T* data = view.typed<T>();
  const Index3& d = view.dims;
  return tbb::parallel_reduce(
      tbb::blocked_range<std::int64_t>(0, d[2]), NonFinite{},
      [&](const tbb::blocked_range<std::int64_t>& r, NonFinite acc) {
        for (std::int64_t k = r.begin(); k != r.end(); ++k)
          for (std::int64_t j = 0; j < d[1]; ++j) {
            const T* row = data + view.offset(0, j, k);
            for (std::int64_t i = 0; i < d[0]; ++i) {
              if (std::isfinite(row[i * view.strides[0]])) continue;
              if (acc.count++ == 0) acc.first = (k * d[1] + j) * d[0] + i;
            }
          }
        return acc;
      },
      [](NonFinite a, const NonFinite& b) {
        a.count += b.count;
        if (a.first < 0 || (b.first >= 0 && b.first < a.first)) a.first = b.first;
        return a;
      });
}

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
};

template <class T>
Range typed_range(const VolumeView& view) {
  const T* data = view.typed<T>();
  const Index3& d = view.dims;
  // min and max are order-independent, so the split TBB picks cannot change the result.
  return tbb::parallel_reduce(
      tbb::blocked_range<std::int64_t>(0, d[2]), Range{},
      [&](const tbb::blocked_range<std::int64_t>& r, Range acc) {
        for (std::int64_t k = r.begin(); k != r.end(); ++k)
          for (std::int64_t j = 0; j < d[1]; ++j) {
            const T* row = data + view.offset(0, j, k);
            T lo = row[0];
            T hi = row[0];
            for (std::int64_t i = 1; i < d[0]; ++i) {
              const T v = row[i * view.strides[0]];
              if constexpr (std::is_floating_point_v<T>) {
                // A NaN must never stay a bound: comparisons with it are all false.
                if (std::isnan(lo)) lo = hi = v;
              }
              if (v < lo) lo = v;
              if (v > hi) hi = v;
            }
            if (static_cast<double>(lo) < acc.lo) acc.lo = static_cast<double>(lo);
            if (static_cast<double>(hi) > acc.hi) acc.hi = static_cast<double>(hi);
          }
        return acc;
      },
      [](Range a, const Range& b) {
        a.lo = std::min(a.lo, b.lo);
        a.hi = std::max(a.hi, b.hi);
        return a;
      });
}

}  // namespace

Volume read_volume(const std::string& input, const RawOptions& raw) {
  if (const std::optional<FieldSpec> spec = parse_field_spec(input)) {
    reject_raw_only_options(input, raw, "procedural field");
    return make_field_volume(*spec);
  }
  const std::string ext = lower_extension(input);
  const bool nrrd = ext == ".nrrd" || ext == ".nhdr";
  const bool vdb = ext == ".vdb";
  if (!nrrd && !vdb) return read_raw(input, raw);

  reject_raw_only_options(input, raw, nrrd ? "NRRD file" : "VDB file");
  Volume volume = nrrd ? read_nrrd(input) : read_vdb(input);
  if (raw.spacing) volume.set_spacing(*raw.spacing);
  if (raw.origin) volume.set_origin(*raw.origin);
  return volume;
}

void check_finite(const VolumeView& view, const std::string& what) {
  if (!is_floating(view.type) || view.sample_count() <= 0) return;
  const NonFinite bad = view.type == ScalarType::Float32 ? count_non_finite<float>(view)
                                                         : count_non_finite<double>(view);
  if (bad.count == 0) return;
  const std::int64_t i = bad.first % view.dims[0];
  const std::int64_t j = bad.first / view.dims[0] % view.dims[1];
  const std::int64_t k = bad.first / view.dims[0] / view.dims[1];
  const Index3 g{view.box.lo[0] + i, view.box.lo[1] + j, view.box.lo[2] + k};
  throw InputError(
      what + ": " + std::to_string(bad.count) + (bad.count == 1 ? " sample is" : " samples are") +
      " NaN or Inf (first at x=" + std::to_string(g[0]) + ", y=" + std::to_string(g[1]) +
      ", z=" + std::to_string(g[2]) + "); isosurfaces need finite values");
}

std::pair<double, double> value_range(const VolumeView& view) {
  if (view.sample_count() <= 0) return {0.0, 0.0};
  const Range r =
      visit_scalar(view.type, [&](auto tag) { return typed_range<decltype(tag)>(view); });
  // Only an all-NaN volume leaves the bounds unset.
  if (r.lo > r.hi)
    return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  return {r.lo, r.hi};
}

}  // namespace isotile
