// The samples' histogram of a volume read box by box (`--iso auto` with --memory), and the error
// for an isovalue that gives no surface, shared by the in-core and out-of-core runs.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>

#include "core/errors.h"
#include "core/progress.h"
#include "core/volume/otsu_isovalue.h"
#include "tiler/volume_source.h"

namespace isotile {

// One streaming pass over `source` in slabs of whole z-planes (rows of one plane where a plane
// alone exceeds a quarter of `memory_budget`; 0: no budget), each slab's histogram merged into
// the volume's (core/volume/otsu_isovalue.h). Reads the input once more than the extraction
// does; the source is rewound before and after. Holds one slab and the histograms (1.5 MiB per
// thread) at a time. `progress`: told of each slab (Stage::Histogram; slabs of at most 16 MiB
// then, so that one takes well under 0.1 s); null: nobody listens.
ValueHistogram source_histogram(VolumeSource& source, std::uint64_t memory_budget,
                                Progress* progress = nullptr);

// That pass itself: `each` is handed every slab in order, as a view of the source's box.
void for_each_slab(VolumeSource& source, std::uint64_t memory_budget, Progress* progress,
                   const std::function<void(const VolumeView&)>& each);

// What throw_no_surface throws: an InputError with the CLI's message, and its parts, so that a
// front end with other ways out (the MeshLab plugin's fields) can word its own advice around
// the library's finding instead of measuring the samples again.
struct NoSurfaceError : InputError {
  NoSurfaceError(std::string message, double iso_, std::optional<std::pair<double, double>> range_,
                 std::string finding_, bool straddled_)
      : InputError(std::move(message)),
        iso(iso_),
        range(range_),
        finding(std::move(finding_)),
        straddled(straddled_) {}
  double iso;
  std::optional<std::pair<double, double>> range;  // the samples' range, where known
  // Where the samples lie: "the samples range from 0 to 255, all below it".
  std::string finding;
  // Samples lie on both sides of iso, yet no face was made (a volume one sample thick, Dual
  // Contouring's border cells): another isovalue inside the range may not help either.
  bool straddled;
};

// NoSurfaceError: the run made no face, most often because no pair of samples straddles `iso`
// (every sample on one side); names the samples' range where known, what it means, and the ways
// out (--iso auto, --allow-empty).
[[noreturn]] void throw_no_surface(double iso,
                                   const std::optional<std::pair<double, double>>& range);
// The same for a streamed run, the range found by one pass over `source` (the out-of-core
// paths' no-face error, whatever the reason: no cells, or a count of no face).
[[noreturn]] void throw_no_surface(VolumeSource& source, std::uint64_t memory_budget, double iso);

}  // namespace isotile
