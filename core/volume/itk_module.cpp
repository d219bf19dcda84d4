// The entry point of the ITK reader module (core/volume/reader_modules.h).
#include "core/volume/reader_modules.h"

extern "C" __attribute__((visibility("default"))) const isotile::ItkReaderModule*
isotile_itk_reader_module_v2() {
  static const isotile::ItkReaderModule table{&isotile::read_itk_info, &isotile::read_itk_data,
                                              &isotile::list_dicom_series};
  return &table;
}
