// The ITK interface when the project is built without ITK (ISOTILE_ITK=OFF).
#include "core/errors.h"
#include "core/volume/itk_reader.h"

namespace isotile {

namespace {
[[noreturn]] void missing(const std::string& what) {
  throw InputError(what +
                   ": reading NIfTI, MetaImage, TIFF and DICOM needs ITK, and this isotile "
                   "was built without it (ISOTILE_ITK=OFF)");
}
}  // namespace

bool itk_available() {
  return false;
}
ItkImageInfo read_itk_info(const ItkInput& input) {
  missing(input.path);
}
void read_itk_data(const ItkInput& input, const ItkImageInfo&, void*) {
  missing(input.path);
}
std::vector<DicomSeriesInfo> list_dicom_series(const std::string& directory) {
  missing(directory);
}
bool is_dicom_file(const std::string&) {
  return false;
}
void write_itk(const std::string& path, const void*, ScalarType, const Index3&, const Vec3d&,
               const Vec3d&, const Mat3&) {
  missing(path);
}

}  // namespace isotile
