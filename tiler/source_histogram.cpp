#include "tiler/source_histogram.h"

#include <algorithm>
#include <sstream>
#include <string>
#include <vector>

#include "core/errors.h"

namespace isotile {

ValueHistogram source_histogram(VolumeSource& source, std::uint64_t memory_budget,
                                Progress* progress) {
  ValueHistogram h;
  for_each_slab(source, memory_budget, progress,
                [&](const VolumeView& slab) { merge(h, value_histogram(slab)); });
  return h;
}

void for_each_slab(VolumeSource& source, std::uint64_t memory_budget, Progress* progress,
                   const std::function<void(const VolumeView&)>& each) {
  const std::uint64_t sample = scalar_size(source.type);
  const std::uint64_t row = static_cast<std::uint64_t>(source.dims[0]) * sample;
  const std::uint64_t plane = row * static_cast<std::uint64_t>(source.dims[1]);
  // A quarter of the budget for the slab; otherwise 64 MiB, which keeps every thread busy.
  std::uint64_t slab_bytes = memory_budget > 0 ? memory_budget / 4 : std::uint64_t{64} << 20;
  // The histogram is a sum of counts: the same for any slab size.
  if (progress) slab_bytes = std::min(slab_bytes, std::uint64_t{16} << 20);
  // Sequential (gzip'd) sources give whole x-y slabs only.
  const bool rows = plane > slab_bytes && !source.sequential();
  const std::int64_t step =
      rows ? std::max<std::int64_t>(
                 1, static_cast<std::int64_t>(slab_bytes / std::max<std::uint64_t>(row, 1)))
           : std::max<std::int64_t>(
                 1, static_cast<std::int64_t>(slab_bytes / std::max<std::uint64_t>(plane, 1)));
  // Stage::Histogram counts the slabs read.
  const std::int64_t y_parts = rows ? (source.dims[1] + step - 1) / step : 1;
  progress_begin(progress, Stage::Histogram,
                 rows ? source.dims[2] * y_parts : (source.dims[2] + step - 1) / step);
  source.rewind();
  std::vector<char> buffer;
  for (std::int64_t z = 0; z < source.dims[2];) {
    Box3 box;
    if (rows) {
      for (std::int64_t y = 0; y < source.dims[1]; y += step) {
        box = {{0, y, z}, {source.dims[0], std::min(source.dims[1], y + step), z + 1}};
        buffer.resize(static_cast<std::size_t>(box.extent(0) * box.extent(1)) * sample);
        source.read(box, buffer.data());
        each(brick_view(source, box, buffer.data()));
        progress_advance(progress);
      }
      ++z;
      continue;
    }
    box = {{0, 0, z}, {source.dims[0], source.dims[1], std::min(source.dims[2], z + step)}};
    buffer.resize(static_cast<std::size_t>(plane * static_cast<std::uint64_t>(box.extent(2))));
    source.read(box, buffer.data());
    each(brick_view(source, box, buffer.data()));
    progress_advance(progress);
    z = box.hi[2];
  }
  source.rewind();
}

void throw_no_surface(VolumeSource& source, std::uint64_t memory_budget, double iso) {
  const ValueHistogram h = source_histogram(source, memory_budget);
  throw_no_surface(iso, std::pair(h.min, h.max));
}

void throw_no_surface(double iso, const std::optional<std::pair<double, double>>& range) {
  // Each number as the shortest text that reads back to it: at ten digits 99.99999999999 read
  // "100", and "no surface at iso 100: the samples range from 0 to 100, all below it".
  std::ostringstream f;
  const bool inside = range && range->first < iso && iso <= range->second;
  if (inside)  // straddled, yet no face
    f << "the samples range from " << number_text(range->first) << " to "
      << number_text(range->second)
      << " but no face crosses it (a volume one sample thick has no cells; Dual Contouring makes "
         "no face where the surface meets only the volume's border)";
  else if (range)
    f << "the samples range from " << number_text(range->first) << " to "
      << number_text(range->second)
      << (iso > range->second ? ", all below it" : ", all at or above it");
  else
    f << "every sample lies on one side of it";
  std::ostringstream s;
  s << "no surface at iso " << number_text(iso) << ": " << f.str()
    << (range ? "" : " (`isotile info` shows the range)")
    << (inside ? "; choose another isovalue or method" : "; choose an isovalue inside the range")
    << ", or --iso auto (or --allow-empty to write the empty mesh)";
  throw NoSurfaceError(s.str(), iso, range, f.str(), inside);
}

}  // namespace isotile
