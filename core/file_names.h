// Case-blind tests of file names. Scanners and older tools write SLICE.DCM, EMBRYO.TIF and
// VOLUME.NII.GZ; every reader, writer and front end takes an extension in any case, so all of
// them compare through these.
#pragma once

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>
#include <string_view>

namespace isotile {

// `s` with ASCII letters lowered (a name's other bytes, UTF-8 included, are left as they are).
inline std::string ascii_lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

// Whether `s` ends with `lower_suffix` (given in lower case) in any case.
inline bool ends_with_ci(std::string_view s, std::string_view lower_suffix) {
  if (s.size() < lower_suffix.size()) return false;
  return ascii_lower(std::string(s.substr(s.size() - lower_suffix.size()))) == lower_suffix;
}

// The last extension of a path in lower case, with its dot (".gz" of "x.nii.gz"; "" for none).
inline std::string lower_extension(const std::filesystem::path& p) {
  return ascii_lower(p.extension().string());
}

}  // namespace isotile
