#include "core/volume/otsu_isovalue.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <bit>
#include <cmath>
#include <type_traits>
#include <vector>

#include "core/errors.h"

namespace isotile {

namespace {

// The bin of a value: the upper 16 bits of its float32 bit pattern made order-preserving (the
// sign bit flipped for positives, every bit flipped for negatives), so bins ascend with values.
int bin_of(double v) {
  const auto bits = std::bit_cast<std::uint32_t>(static_cast<float>(v));
  const std::uint32_t key = (bits & 0x80000000u) ? ~bits : bits | 0x80000000u;
  return static_cast<int>(key >> 16);
}

// `n` samples of value v.
void add(ValueHistogram& h, double v, std::uint64_t n = 1) {
  if (std::isnan(v)) return;
  const int b = bin_of(v);
  if (h.count[b] == 0) {
    h.lo[b] = h.hi[b] = v;
  } else {
    h.lo[b] = std::min(h.lo[b], v);
    h.hi[b] = std::max(h.hi[b], v);
  }
  h.count[b] += n;
}

// samples, min and max from the bins (the lowest bin's lowest sample, the highest's highest).
void finish(ValueHistogram& h) {
  h.samples = 0;
  int first = -1, last = -1;
  for (int b = 0; b < ValueHistogram::kBins; ++b) {
    if (h.count[b] == 0) continue;
    h.samples += h.count[b];
    if (first < 0) first = b;
    last = b;
  }
  h.min = first < 0 ? 0.0 : h.lo[first];
  h.max = last < 0 ? 0.0 : h.hi[last];
}

// 8- and 16-bit integers: a count per value (256 or 65536 of them), then each value's count into
// its bin; the same histogram as sample by sample, at a fraction of the work per sample (one
// increment instead of a conversion to float, a bin and a minimum and maximum). Threads count
// planes apart and add up.
template <typename T>
void add_small_integers(const VolumeView& view, ValueHistogram& out) {
  using U = std::make_unsigned_t<T>;
  constexpr std::size_t kValues = std::size_t{1} << (8 * sizeof(T));
  const T* data = view.typed<T>();
  tbb::enumerable_thread_specific<std::vector<std::uint64_t>> local(
      [] { return std::vector<std::uint64_t>(kValues, 0); });
  tbb::parallel_for(std::int64_t{0}, view.dims[2], [&](std::int64_t k) {
    std::vector<std::uint64_t>& counts = local.local();
    for (std::int64_t j = 0; j < view.dims[1]; ++j) {
      const T* row = data + view.offset(0, j, k);
      for (std::int64_t i = 0; i < view.dims[0]; ++i)
        ++counts[static_cast<U>(row[i * view.strides[0]])];
    }
  });
  std::vector<std::uint64_t> counts(kValues, 0);
  for (const std::vector<std::uint64_t>& c : local)
    for (std::size_t v = 0; v < kValues; ++v) counts[v] += c[v];
  for (std::size_t v = 0; v < kValues; ++v)
    if (counts[v] > 0) add(out, static_cast<double>(static_cast<T>(static_cast<U>(v))), counts[v]);
  finish(out);
}

}  // namespace

void merge(ValueHistogram& into, const ValueHistogram& other) {
  if (other.samples == 0) return;
  for (int b = 0; b < ValueHistogram::kBins; ++b) {
    if (other.count[b] == 0) continue;
    if (into.count[b] == 0) {
      into.lo[b] = other.lo[b];
      into.hi[b] = other.hi[b];
    } else {
      into.lo[b] = std::min(into.lo[b], other.lo[b]);
      into.hi[b] = std::max(into.hi[b], other.hi[b]);
    }
    into.count[b] += other.count[b];
  }
  finish(into);
}

ValueHistogram value_histogram(const VolumeView& view) {
  ValueHistogram out;
  // Otherwise one histogram per thread (1.5 MiB each), merged at the end: counts, minima and
  // maxima do not depend on which thread saw which slab.
  tbb::enumerable_thread_specific<ValueHistogram> local;
  visit_scalar(view.type, [&](auto tag) {
    using T = decltype(tag);
    if constexpr (std::is_integral_v<T> && sizeof(T) <= 2) {
      add_small_integers<T>(view, out);
    } else {
      const T* data = view.typed<T>();
      tbb::parallel_for(std::int64_t{0}, view.dims[2], [&](std::int64_t k) {
        ValueHistogram& h = local.local();
        for (std::int64_t j = 0; j < view.dims[1]; ++j) {
          const T* row = data + view.offset(0, j, k);
          for (std::int64_t i = 0; i < view.dims[0]; ++i)
            add(h, static_cast<double>(row[i * view.strides[0]]));
        }
      });
    }
  });
  for (ValueHistogram& h : local) {
    finish(h);
    merge(out, h);
  }
  return out;
}

double otsu_isovalue(const ValueHistogram& h) {
  if (h.samples == 0) throw InputError("no samples to choose an isovalue from");
  if (!(h.min < h.max))
    throw InputError("every sample is " + number_text(h.min) +
                     ": no isovalue separates an inside from an outside");
  // Each bin's samples stand at the middle of its bounds (exact for every bin holding one value,
  // as every bin of an 8- or 16-bit volume below 256 does).
  double total_weight = 0, total_sum = 0;
  for (int b = 0; b < ValueHistogram::kBins; ++b) {
    if (h.count[b] == 0) continue;
    const double n = static_cast<double>(h.count[b]);
    total_weight += n;
    total_sum += n * (0.5 * (h.lo[b] + h.hi[b]));
  }
  // Between-class variance w0 w1 (mu0 - mu1)^2 for a split after each non-empty bin; the first
  // largest wins (a deterministic tie-break).
  double w0 = 0, s0 = 0, best = -1;
  int best_bin = -1;
  for (int b = 0; b < ValueHistogram::kBins; ++b) {
    if (h.count[b] == 0) continue;
    const double n = static_cast<double>(h.count[b]);
    w0 += n;
    s0 += n * (0.5 * (h.lo[b] + h.hi[b]));
    const double w1 = total_weight - w0;
    if (w1 <= 0) break;
    const double mu0 = s0 / w0, mu1 = (total_sum - s0) / w1;
    const double between = w0 * w1 * (mu0 - mu1) * (mu0 - mu1);
    if (between > best) {
      best = between;
      best_bin = b;
    }
  }
  // All samples in one bin but not one value (a float volume spanning less than a bin): split
  // that bin's range in the middle.
  if (best_bin < 0) {
    const double mid = h.min + 0.5 * (h.max - h.min);
    return mid > h.min ? mid : h.max;
  }
  int next = best_bin + 1;
  while (h.count[next] == 0) ++next;
  const double below = h.hi[best_bin], above = h.lo[next];
  const double mid = below + 0.5 * (above - below);
  return mid > below ? mid : above;
}

}  // namespace isotile
