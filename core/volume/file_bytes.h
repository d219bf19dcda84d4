// Bytes of a file read where asked, bounds checked against its size, and little- or big-endian
// numbers from them: what the checks made before ITK and GDCM read files with
// (core/volume/dicom_check.cpp, tiff_check.cpp). Internal to core/volume.
#pragma once

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/errors.h"

namespace isotile::file_check {

template <class T>
T get(const unsigned char* p, bool swap) {
  T v;
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  std::memcpy(&v, b, sizeof(T));
  return v;
}

// Bytes of a file read where asked, bounds checked against its size.
class FileBytes {
 public:
  explicit FileBytes(const std::string& path) : path_(path), f_(path, std::ios::binary) {
    if (!f_) throw IoError("cannot open " + path + ": " + std::strerror(errno));
    std::error_code ec;
    size_ = std::filesystem::file_size(path, ec);
    if (ec) throw IoError("cannot open " + path + ": " + ec.message());
  }
  std::uint64_t size() const { return size_; }
  bool fits(std::uint64_t at, std::uint64_t n) const { return at <= size_ && n <= size_ - at; }
  // n bytes at `at` (n small); false past the end.
  bool read(std::uint64_t at, void* out, std::size_t n) {
    if (!fits(at, n)) return false;
    f_.clear();
    f_.seekg(static_cast<std::streamoff>(at));
    f_.read(static_cast<char*>(out), static_cast<std::streamsize>(n));
    return static_cast<std::size_t>(f_.gcount()) == n;
  }

 private:
  std::string path_;
  std::ifstream f_;
  std::uint64_t size_ = 0;
};

}  // namespace isotile::file_check
