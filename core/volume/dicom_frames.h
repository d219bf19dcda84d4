// The geometry of a DICOM file's frames from its own elements, where GDCM's is not to be trusted:
// enhanced multi-frame files (Enhanced CT, MR, PET...) give each frame's position, orientation
// and pixel spacing in functional groups, and GDCM places their frames by the step between the
// first two, falling back to a spacing of 1, 1, 1 where the steps differ; RT Dose gives its
// frames' offsets along the normal (GridFrameOffsetVector), which GDCM refuses when they
// descend and does not check for gaps. isotile reads them so that they can be checked like the
// slices of a series (slice_stack.h). Other multi-frame files give one position for all frames;
// GDCM stacks those frames as slices whatever they are, so isotile reads what they run over.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/volume/volume.h"

namespace isotile {

struct DicomFrames {
  bool functional_groups = false;  // PerFrameFunctionalGroupsSequence present (an enhanced file)
  // Each frame's ImagePositionPatient, in frame order: from the functional groups, or RT Dose's
  // position plus each GridFrameOffsetVector offset along the normal; empty where the file gives
  // none per frame (a single-frame image, or a multi-frame one with one position and a spacing).
  std::vector<Vec3d> positions;
  // ImageOrientationPatient (row, then column cosines) and PixelSpacing (between rows, then
  // between columns), alike in every frame, where the functional groups give them.
  std::optional<std::array<double, 6>> orientation;
  std::optional<std::array<double, 2>> pixel_spacing;
  // The pixel spacing GDCM reads for this kind of image (PixelSpacing for CT and MR,
  // ImagerPixelSpacing for projections...; gdcm::ImageHelper) is in the file, at the top level
  // or in the functional groups. Without it GDCM takes 1 mm.
  bool spacing_known = true;
  std::string spacing_element;  // that element, e.g. "PixelSpacing (0028,0030)"
  // A multi-frame file whose frames carry no positions of their own (no functional groups, not
  // RT Dose): GDCM stacks them as slices whatever they are and puts them 1 mm apart unless the
  // element it reads the distance from is in the file (SpacingBetweenSlices for MR and NM,
  // none for most kinds). Empty where they are slices as far as the file says, else what they
  // run over by FrameIncrementPointer: time (FrameTime, FrameTimeVector: a cine loop, a
  // dynamic series) or something else that differs from frame to frame (NM's detectors,
  // rotations, energy windows, gates; angles).
  std::string frames_over;
  // Why GDCM does not know the distance between such frames ("no SpacingBetweenSlices
  // (0018,0088)"); empty where it does.
  std::string frame_spacing_unknown;
};

// `frames`: the file's frames as GDCM counts them. Throws InputError naming the file and the
// frame where frames differ in what one volume needs alike (orientation, pixel spacing, rescale),
// some frames have a position and others none, or RT Dose's offsets are not one per frame.
DicomFrames read_dicom_frames(const std::string& path, std::int64_t frames);

// The checks read_dicom_frames makes of one file's image, for the slices of a series, whose
// values ITK's reader gives: throw InputError for PhotometricInterpretation MONOCHROME1 (ITK
// inverts its samples), and for a pixel spacing (`element` named in the message, `values` its
// text, "0.5\\0.5") that is not two positive distances (GDCM takes 1 mm for a 0).
void check_photometric(const std::string& path, const std::string& photometric);
void check_pixel_spacing(const std::string& path, const std::string& element,
                         const std::string& values);

}  // namespace isotile
