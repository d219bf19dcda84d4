// Planes of a volume from their positions: DICOM slices (one file each) or the frames of one
// multi-frame file. A volume is made only of planes that lie evenly along their common normal;
// anything else (a gap, two planes at one place, a tilted gantry, a plane out of line) would need
// resampling, which would silently change the data, and is an error naming the planes.
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "core/volume/volume.h"

namespace isotile {

struct SliceStack {
  std::vector<std::size_t> order;  // the planes along the normal, first one first
  double step = 0;                 // the distance between neighbours, along the normal
};

// What the planes are called in messages: "slice" and "slices", or "frame" and "frames".
struct PlaneNoun {
  const char* one;
  const char* many;
};

// `origins`: each plane's first sample (ImagePositionPatient), at least two; `normal`: a unit
// vector. `noun` names the planes and `name(k)` plane k in messages. Throws InputError prefixed
// with `input`.
SliceStack stack_along_normal(const std::string& input, const std::vector<Vec3d>& origins,
                              const Vec3d& normal, PlaneNoun noun,
                              const std::function<std::string(std::size_t)>& name);

}  // namespace isotile
