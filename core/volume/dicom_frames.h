// The geometry of each frame of an enhanced multi-frame DICOM file (Enhanced CT, MR, PET...),
// from its functional groups: where each frame lies, how it is turned, its pixel spacing. GDCM
// places the frames of such a file by the step between the first two it finds, and falls back to
// a spacing of 1, 1, 1 where the steps differ; isotile reads them so that they can be checked
// like the slices of a series (slice_stack.h).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/volume/volume.h"

namespace isotile {

struct DicomFrames {
  // Each frame's ImagePositionPatient, in frame order; empty where the file has none per frame
  // (a single-frame image, or a multi-frame one that only gives one position and a spacing).
  std::vector<Vec3d> positions;
  // ImageOrientationPatient (row, then column cosines) and PixelSpacing (between rows, then
  // between columns), alike in every frame, where the functional groups give them.
  std::optional<std::array<double, 6>> orientation;
  std::optional<std::array<double, 2>> pixel_spacing;
};

// Throws InputError naming the file and the frame where frames differ in what one volume needs
// alike (orientation, pixel spacing, rescale), or some frames have a position and others none.
DicomFrames read_dicom_frames(const std::string& path, std::int64_t frames);

}  // namespace isotile
