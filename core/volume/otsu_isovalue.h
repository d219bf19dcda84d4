// An isovalue chosen from the samples' histogram (`isotile extract --iso auto`, the MeshLab
// filter, the Python module): Otsu's threshold, the value that splits the samples into two
// classes with the largest between-class variance w0 w1 (mu0 - mu1)^2 (Otsu 1979). On a scan
// that is the boundary between the two dominant materials (air and tissue in CT, background and
// specimen in microscopy); on a distance or implicit field, a level between its two halves.
//
// The histogram is exact in what the rule needs and the same for any thread count or brick
// order: 65536 bins, each sample going to the bin of the upper 16 bits of its value as an
// order-preserving float32 key (bins are narrow where values are small, about 1/128 of a value's
// magnitude), each bin holding its count and its lowest and highest sample. Counts add, bounds
// take min and max: histograms of bricks merge into the histogram of the volume in any order.
// The threshold lies halfway between the highest sample of the lower class and the lowest of the
// upper one, so no sample equals it (no crossing sits on a sample).
#pragma once

#include <cstdint>
#include <vector>

#include "core/volume/volume.h"

namespace isotile {

struct ValueHistogram {
  static constexpr int kBins = 1 << 16;
  std::vector<std::uint64_t> count = std::vector<std::uint64_t>(kBins, 0);
  std::vector<double> lo = std::vector<double>(kBins, 0.0);  // smallest sample of each bin
  std::vector<double> hi = std::vector<double>(kBins, 0.0);  // largest sample of each bin
  std::uint64_t samples = 0;                                 // NaN samples are not counted
  double min = 0, max = 0;                                   // of every sample; 0 when none
};

// Histogram of every sample of `view` (its dims, not its global box), on all threads.
ValueHistogram value_histogram(const VolumeView& view);

// Adds `other` into `into`.
void merge(ValueHistogram& into, const ValueHistogram& other);

// Otsu's threshold of the histogram, strictly between its lowest and highest sample, so that
// samples >= it (inside) and samples below it both exist. Throws InputError when there is no
// such value: no samples, or all of one value.
double otsu_isovalue(const ValueHistogram& histogram);

}  // namespace isotile
