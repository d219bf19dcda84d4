// Volumes read through ITK 5.2's image IO: NIfTI, MetaImage, TIFF (one multi-page file, or a
// stack of single-page files) and DICOM series (through GDCM). ITK lives in itk_reader.cpp alone
// (its templates are slow to compile); this interface hands back plain buffers and headers.
//
// Geometry is ITK's: world (LPS for medical images) position of sample g is
// origin + direction * (spacing * g). Sample values are rescaled where the format says so
// (DICOM's and NIfTI's slope and intercept), in the type ITK picks for the rescaled values.
#pragma once

#include <string>
#include <vector>

#include "core/volume/volume.h"

namespace isotile {

// What to read: a file, a directory (DICOM series or TIFF slices), or a printf-style pattern of
// numbered TIFF slices (`slice_%03d.tif`).
struct ItkInput {
  enum class Kind { Nifti, MetaImage, Tiff, TiffStack, Dicom };
  Kind kind = Kind::Nifti;
  std::string path;
  std::string series;  // DICOM: the SeriesInstanceUID to read (empty: the only one)
  // --spacing replaces the file's spacing: a DICOM series without PixelSpacing is then read.
  bool spacing_given = false;
};

struct ItkImageInfo {
  ScalarType type = ScalarType::UInt8;
  Index3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  Vec3d origin{0, 0, 0};
  Mat3 direction = kIdentity3;
  std::string format;  // "NIfTI", "MetaImage", "TIFF", "DICOM"
  bool rescaled = false;
  double rescale_slope = 1;
  double rescale_intercept = 0;
  RescaleRange rescale_range;      // the slices' (the two above are the first slice's)
  std::vector<std::string> files;  // stacks: the slices in z order
  // A multi-frame DICOM file whose frames are not in order along their normal: the frame (in
  // the file) of each z, lowest first; empty where they are.
  std::vector<std::size_t> frame_order;
  std::string series_uid, series_description;
};

struct DicomSeriesInfo {
  std::string uid, description;
  std::int64_t columns = 0, rows = 0, files = 0;
};

// False when the project was built without ITK (ISOTILE_ITK=OFF); the functions below then
// throw InputError saying so.
bool itk_available();

// The header: dims, type, geometry. Throws InputError (one line, naming the input) for
// anything ITK or GDCM refuses, several DICOM series without `series`, unequal or tilted
// slices.
ItkImageInfo read_itk_info(const ItkInput& input);
// The samples, x fastest, into `out` (dims product times the type's size bytes).
void read_itk_data(const ItkInput& input, const ItkImageInfo& info, void* out);

// The DICOM series in a directory.
std::vector<DicomSeriesInfo> list_dicom_series(const std::string& directory);
// True when GDCM recognises `path` as a DICOM file.
bool is_dicom_file(const std::string& path);

// Writes a volume through ITK (the file's extension picks the format: .nii, .nii.gz, .mha, .mhd,
// .tif); `direction` and `origin` go into the header as ITK maps them. Used by the tests.
void write_itk(const std::string& path, const void* data, ScalarType type, const Index3& dims,
               const Vec3d& spacing, const Vec3d& origin, const Mat3& direction);

}  // namespace isotile
