// The samples' range and the check that they are finite, in one pass over them.
//
// An isosurface call with scikit-image's conventions needs both before it extracts: NaN and Inf
// are rejected (check_finite) and the level is checked against, or taken from, the range
// (value_range). One scan answers both, the rows of a contiguous x axis read in SIMD-friendly
// lanes; value_range() (core/volume/volume_io.h) is the same scan, defined in finite_range.cpp.
#pragma once

#include <string>
#include <utility>

#include "core/volume/volume.h"

namespace isotile {

// check_finite(view, what) and then value_range(view): the same error (InputError naming how many
// samples are NaN or Inf and where the first is) or the same minimum and maximum (0, 0 for an
// empty view; a zero bound is +0.0). Deterministic for any thread count.
std::pair<double, double> finite_value_range(const VolumeView& view, const std::string& what);

}  // namespace isotile
