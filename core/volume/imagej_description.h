// What ImageJ (and tifffile's imagej=True) writes in a TIFF's first ImageDescription
// ("ImageJ=1.54f\nimages=20\nslices=20\nunit=micron\nspacing=2.5\n..."), as far as a volume
// cares: the axes its pages interleave and its calibration.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "core/volume/volume.h"

namespace isotile {

// The description's `key=value` lines (none unless it begins with "ImageJ="); values written
// with Java's \uXXXX escapes (ImageJ's "\u00B5m") decoded to UTF-8.
std::map<std::string, std::string> imagej_properties(const std::string& description);

// Its channels, slices and time points (frames), and its count of planes (images), 1 where it
// does not say.
struct ImageJShape {
  std::uint64_t channels = 1, slices = 1, frames = 1, images = 1;
  // Pages of more than one of these axes interleave them (one alone, whatever ImageJ or tifffile
  // calls it, is a stack of planes: tifffile's imagej=True labels a plain stack's z as channels).
  bool hyperstack() const { return (channels > 1) + (slices > 1) + (frames > 1) > 1; }
};
ImageJShape imagej_shape(const std::map<std::string, std::string>& properties);

// The calibration as ImageJ reads it: pixel width and height 1 / XResolution and 1 / YResolution
// (pixels per unit; 0 where the tag is absent), voxel depth `spacing=` (1 where absent), in the
// unit `unit=` names; centimetre resolution tags (ResolutionUnit 3) with `unit=um` are scaled to
// micrometres (ImageJ's own rule, for "um" alone); the centimetre and the inch are given in mm, as
// ITK gives resolution tags in those units. None where uncalibrated (`unit=pixel`, or neither unit
// nor depth). Throws InputError, naming `path`, for a depth that is no number or axes in different
// units.
struct ImageJSpacing {
  Vec3d spacing{1, 1, 1};
  std::string unit;  // "micron", "µm", "nm"...; "mm" for cm and inch; empty where none is named
};
std::optional<ImageJSpacing> imagej_spacing(const std::string& path,
                                            const std::map<std::string, std::string>& properties,
                                            double x_resolution, double y_resolution,
                                            std::uint64_t resolution_unit);

}  // namespace isotile
