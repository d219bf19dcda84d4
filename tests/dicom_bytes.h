// DICOM files written element by element (explicit VR little endian), for tests that need files
// no tool at hand writes: multi-frame files with functional groups, files with chosen faults.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace isotile::testing::dicom {

inline std::string u16(std::uint16_t v) {
  return {static_cast<char>(v & 0xff), static_cast<char>(v >> 8)};
}

inline std::string u32(std::uint32_t v) {
  return u16(static_cast<std::uint16_t>(v & 0xffff)) + u16(static_cast<std::uint16_t>(v >> 16));
}

// One element; its value padded to an even length as the standard pads it (UI and OB with a
// zero byte, text with a space).
inline std::string element(std::uint16_t group, std::uint16_t elem, const std::string& vr,
                           std::string value) {
  if (value.size() % 2) value += (vr == "UI" || vr == "OB") ? '\0' : ' ';
  std::string out = u16(group) + u16(elem) + vr;
  if (vr == "OB" || vr == "OW" || vr == "SQ" || vr == "UN" || vr == "UT")
    out += u16(0) + u32(static_cast<std::uint32_t>(value.size()));
  else
    out += u16(static_cast<std::uint16_t>(value.size()));
  return out + value;
}

// A decimal string: the numbers to 10 significant digits, separated by backslashes.
inline std::string ds(const std::vector<double>& values) {
  std::string text;
  for (const double v : values) {
    char b[32];
    std::snprintf(b, sizeof b, "%.10g", v);
    text += (text.empty() ? "" : "\\") + std::string(b);
  }
  return text;
}

// A sequence of items of defined length, each item the elements given (in tag order).
inline std::string sequence(std::uint16_t group, std::uint16_t elem,
                            const std::vector<std::string>& items) {
  std::string body;
  for (const std::string& item : items)
    body += u16(0xFFFE) + u16(0xE000) + u32(static_cast<std::uint32_t>(item.size())) + item;
  return element(group, elem, "SQ", body);
}

// A Part 10 file: preamble, marker, meta group (explicit VR little endian), then `body` (the data
// set's elements in tag order).
inline std::string part10(const std::string& sop_class, const std::string& sop_instance,
                          const std::string& body) {
  const std::string meta = element(0x0002, 0x0001, "OB", std::string("\0\1", 2)) +
                           element(0x0002, 0x0002, "UI", sop_class) +
                           element(0x0002, 0x0003, "UI", sop_instance) +
                           element(0x0002, 0x0010, "UI", "1.2.840.10008.1.2.1");
  return std::string(128, '\0') + "DICM" +
         element(0x0002, 0x0000, "UL", u32(static_cast<std::uint32_t>(meta.size()))) + meta + body;
}

}  // namespace isotile::testing::dicom
