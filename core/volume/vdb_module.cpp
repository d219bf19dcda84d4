// The entry point of the OpenVDB reader module (core/volume/reader_modules.h).
#include "core/volume/reader_modules.h"

extern "C" __attribute__((visibility("default"))) const isotile::VdbReaderModule*
isotile_vdb_reader_module_v1() {
  static const isotile::VdbReaderModule table{&isotile::open_vdb};
  return &table;
}
