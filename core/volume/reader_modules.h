// The OpenVDB and ITK readers as loadable modules. Their libraries cost every process that links
// them about 55 ms of dynamic loading before main (docs/benchmarks.md, "The whole process"), so
// the isotile program does not link them: it loads libisotile_vdb_reader.so or
// libisotile_itk_reader.so the first time it reads a .vdb or ITK-format input
// (tiler/reader_modules.cpp). The library (isotile::core), the tests and the MeshLab plugin link
// the readers directly.
//
// Each module exports one C function, taking nothing, that returns its table of the reader's
// functions. The module and the program come from one build (they are installed together), so the
// table passes C++ types; the version in the function's name changes with the table.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/volume/itk_reader.h"
#include "core/volume/volume_io.h"

namespace isotile {

struct VdbReaderModule {
  std::unique_ptr<VdbVolume> (*open_vdb)(const std::string& path);
};
inline constexpr char kVdbReaderModule[] = "libisotile_vdb_reader.so";
inline constexpr char kVdbReaderEntry[] = "isotile_vdb_reader_module_v1";

// The ITK functions that the program's code calls (itk_available, is_dicom_file and write_itk
// serve only the library's other users).
struct ItkReaderModule {
  ItkImageInfo (*read_itk_info)(const ItkInput& input);
  void (*read_itk_data)(const ItkInput& input, const ItkImageInfo& info, void* out);
  std::vector<DicomSeriesInfo> (*list_dicom_series)(const std::string& directory);
};
inline constexpr char kItkReaderModule[] = "libisotile_itk_reader.so";
inline constexpr char kItkReaderEntry[] = "isotile_itk_reader_module_v2";

}  // namespace isotile
