// The OpenVDB and ITK readers of the isotile program and the Python extension: the modules of
// core/volume/reader_modules.h, loaded the first time they are needed. This file takes the place
// of the readers themselves in those objects (tiler/CMakeLists.txt, python/CMakeLists.txt), so a
// run that reads neither format never loads OpenVDB or ITK.
#include <dlfcn.h>

#include <filesystem>
#include <string>

#include "core/errors.h"
#include "core/volume/reader_modules.h"

namespace isotile {

namespace {

namespace fs = std::filesystem;

// The folder of the object (program or shared library) that holds this code, found with dladdr
// on one of its functions: the isotile program, the Python extension or a plugin loaded into
// MeshLab alike, whatever the host process is. /proc/self/exe's folder if dladdr cannot say.
fs::path own_folder() {
  std::error_code ec;
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&own_folder), &info) != 0 && info.dli_fname != nullptr &&
      *info.dli_fname != '\0') {
    const fs::path object = fs::canonical(info.dli_fname, ec);
    if (!ec) return object.parent_path();
  }
  const fs::path program = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path(".") : program.parent_path();
}

// Loads `file` from where it is installed relative to the object holding this code
// (ISOTILE_MODULE_DIR, from that object's install folder), from that object's own folder (the
// build tree), or from the absolute install folder (ISOTILE_MODULE_INSTALL_DIR: a host that
// was moved or copied), and returns its table. Throws IoError naming `input`, the module and why,
// when none works (a broken or partial installation).
template <class Table>
const Table& load_module(const char* file, const char* entry, const char* formats,
                         const std::string& input) {
  std::error_code ec;
  const fs::path dir = own_folder();
  std::string looked, why;
  for (const fs::path& path : {(dir / ISOTILE_MODULE_DIR / file).lexically_normal(), dir / file,
                               fs::path(ISOTILE_MODULE_INSTALL_DIR) / file}) {
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
