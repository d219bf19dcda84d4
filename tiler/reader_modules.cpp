// The isotile program's OpenVDB and ITK readers: the modules of core/volume/reader_modules.h,
// loaded the first time they are needed. This file takes the place of the readers themselves in
// the program (tiler/CMakeLists.txt), so a run that reads neither format never loads OpenVDB or
// ITK.
#include <dlfcn.h>

#include <filesystem>
#include <string>

#include "core/errors.h"
#include "core/volume/reader_modules.h"

namespace isotile {

namespace {

namespace fs = std::filesystem;

// Loads `file` from where it is installed (ISOTILE_MODULE_DIR, relative to the program's folder)
// or, in the build tree, from the program's folder, and returns its table. Throws IoError naming
// `input`, the module and why, when neither works (a broken or partial installation).
template <class Table>
const Table& load_module(const char* file, const char* entry, const char* formats,
                         const std::string& input) {
  std::error_code ec;
  const fs::path program = fs::read_symlink("/proc/self/exe", ec);
  const fs::path dir = ec ? fs::path(".") : program.parent_path();
  std::string looked, why;
  for (const fs::path& path : {(dir / ISOTILE_MODULE_DIR / file).lexically_normal(), dir / file}) {
    looked += (looked.empty() ? "" : ", ") + path.string();
    if (!fs::exists(path, ec)) continue;
    void* module = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!module) {
      why = dlerror();
      continue;
    }
    const auto table = reinterpret_cast<const Table* (*)()>(dlsym(module, entry));
    if (!table) {
      why = path.string() + " has no " + entry + " (from another isotile build?)";
      continue;
    }
    return *table();  // never unloaded: its objects (an open VdbVolume) may outlive any caller
  }
  throw IoError(input + ": reading " + formats + " needs isotile's module " + file + ", which " +
                (why.empty() ? "is not installed (looked in " + looked + ")" : "failed: " + why));
}

const VdbReaderModule& vdb_module(const std::string& input) {
  static const VdbReaderModule& table =
      load_module<VdbReaderModule>(kVdbReaderModule, kVdbReaderEntry, "OpenVDB files", input);
  return table;
}

}  // namespace

std::unique_ptr<VdbVolume> open_vdb(const std::string& path) {
  return vdb_module(path).open_vdb(path);
}

#ifdef ISOTILE_LAZY_ITK

namespace {
const ItkReaderModule& itk_module(const std::string& input) {
  static const ItkReaderModule& table = load_module<ItkReaderModule>(
      kItkReaderModule, kItkReaderEntry, "NIfTI, MetaImage, TIFF and DICOM", input);
  return table;
}
}  // namespace

ItkImageInfo read_itk_info(const ItkInput& input) {
  return itk_module(input.path).read_itk_info(input);
}
void read_itk_data(const ItkInput& input, const ItkImageInfo& info, void* out) {
  itk_module(input.path).read_itk_data(input, info, out);
}
std::vector<DicomSeriesInfo> list_dicom_series(const std::string& directory) {
  return itk_module(directory).list_dicom_series(directory);
}

#endif

}  // namespace isotile
