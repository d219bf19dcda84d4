// ImageJ's TIFF description (imagej_description.h).
#include "core/volume/imagej_description.h"

#include <cmath>
#include <cstdlib>

#include "core/errors.h"

namespace isotile {

namespace {

// Java's Properties.load decodes \uXXXX; ImageJ writes units outside ASCII so ("\u00B5m").
std::string unescape(const std::string& text) {
  std::string out;
  for (std::size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '\\' && i + 5 < text.size() && text[i + 1] == 'u') {
      char* stop = nullptr;
      const std::string hex = text.substr(i + 2, 4);
      const unsigned long c = std::strtoul(hex.c_str(), &stop, 16);
      if (hex.size() == 4 && *stop == '\0') {
        if (c < 0x80) {
          out += static_cast<char>(c);
        } else if (c < 0x800) {
          out += static_cast<char>(0xC0 | (c >> 6));
          out += static_cast<char>(0x80 | (c & 0x3F));
        } else {
          out += static_cast<char>(0xE0 | (c >> 12));
          out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
          out += static_cast<char>(0x80 | (c & 0x3F));
        }
        i += 5;
        continue;
      }
    }
    out += text[i];
  }
  return out;
}

}  // namespace

std::map<std::string, std::string> imagej_properties(const std::string& description) {
  std::map<std::string, std::string> out;
  if (description.rfind("ImageJ=", 0) != 0) return out;
  std::size_t at = 0;
  while (at < description.size()) {
    std::size_t end = description.find('\n', at);
    if (end == std::string::npos) end = description.size();
    const std::string line = description.substr(at, end - at);
    const std::size_t eq = line.find('=');
    if (eq != std::string::npos) out[line.substr(0, eq)] = unescape(line.substr(eq + 1));
    at = end + 1;
  }
  return out;
}

ImageJShape imagej_shape(const std::map<std::string, std::string>& properties) {
  ImageJShape shape;
  const auto count = [&](const char* key, std::uint64_t& n) {
    const auto found = properties.find(key);
    if (found == properties.end()) return;
    std::uint64_t v = 0;
    for (const char c : found->second) {
      if (c < '0' || c > '9' || v >= (1u << 30)) break;
      v = v * 10 + static_cast<std::uint64_t>(c - '0');
    }
    n = v;
  };
  count("channels", shape.channels);
  count("slices", shape.slices);
  count("frames", shape.frames);
  count("images", shape.images);
  return shape;
}

std::optional<ImageJSpacing> imagej_spacing(const std::string& path,
                                            const std::map<std::string, std::string>& properties,
                                            double x_resolution, double y_resolution,
                                            std::uint64_t resolution_unit) {
  const auto get = [&](const char* key) {
    const auto found = properties.find(key);
    return found == properties.end() ? std::string() : found->second;
  };
  const std::string unit = get("unit"), depth_text = get("spacing");
  const bool uncalibrated = unit.empty() || unit == "pixel" || unit == "pixels";
  if (uncalibrated && depth_text.empty()) return std::nullopt;
  for (const char* key : {"yunit", "zunit"}) {
    const std::string other = get(key);
    if (!other.empty() && other != unit)
      throw InputError(path + ": ImageJ's calibration has axes in different units (" + unit + ", " +
                       other + "); give the spacing in one with --spacing X,Y,Z");
  }
  double depth = 1;
  if (!depth_text.empty()) {
    char* stop = nullptr;
    depth = std::abs(std::strtod(depth_text.c_str(), &stop));  // ImageJ takes it so
    if (*stop != '\0' || !std::isfinite(depth) || depth == 0)
      throw InputError(path + ": ImageJ's voxel depth 'spacing=" + depth_text +
                       "' is not a number other than 0");
  }
  ImageJSpacing out;
  const double x = x_resolution > 0 ? 1 / x_resolution : 1;
  const double y = y_resolution > 0 ? 1 / y_resolution : x;
  // Resolution tags per centimetre with "um" named: ImageJ scales the pixel size by 10^4 (its
  // FileOpener; "micron" and "µm" it leaves as they are).
  const double pixel = resolution_unit == 3 && unit == "um" ? 1e4 : 1;
  const double mm = unit == "inch" ? 25.4 : unit == "cm" ? 10 : 1;
  out.spacing = {mm * pixel * x, mm * pixel * y, mm * depth};
  out.unit = mm != 1 ? "mm" : uncalibrated ? "" : unit;
  return out;
}

}  // namespace isotile
