#include "core/volume/text_samples.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>

#include "core/errors.h"
#include "core/volume/scalar_type.h"

namespace isotile {

namespace {

std::pair<double, double> integer_range(ScalarType t) {
  switch (t) {
    case ScalarType::Int8:
      return {-128, 127};
    case ScalarType::UInt8:
      return {0, 255};
    case ScalarType::Int16:
      return {-32768, 32767};
    case ScalarType::UInt16:
      return {0, 65535};
    case ScalarType::Int32:
      return {-2147483648.0, 2147483647.0};
    default:
      return {0, 4294967295.0};
  }
}

}  // namespace

void verify_text_samples(const TextSamples& text, const void* samples, const Index3& dims) {
  std::ifstream f(text.file, std::ios::binary);
  if (!f) throw IoError("cannot open " + text.file + ": " + std::strerror(errno));
  f.seekg(static_cast<std::streamoff>(text.offset));
  const bool floating = is_floating(text.type);
  const auto at = [&](std::int64_t n) {
    return "sample " + std::to_string(n) + " (x=" + std::to_string(n % dims[0]) +
           ", y=" + std::to_string(n / dims[0] % dims[1]) +
           ", z=" + std::to_string(n / dims[0] / dims[1]) + ")";
  };
  const auto refuse = [&](std::int64_t n, const std::string& token, const std::string& why) {
    throw InputError(text.file + ": " + text.what + " " + at(n) + " is '" + token + "', " + why);
  };
  std::string token;
  std::int64_t n = text.first;
  while (n < text.first + text.count && f >> token) {
    std::string_view t = token;
    if (text.commas) {
      if (t == ",") continue;
      t.remove_prefix(std::min(t.find_first_not_of(','), t.size()));
      // A comma after the number ("5,") teem's sscanf leaves unread.
      while (!t.empty() && t.back() == ',') t.remove_suffix(1);
      if (t.empty()) continue;
    }
    double stored = 0;
    visit_scalar(text.type, [&](auto tag) {
      using T = decltype(tag);
      T v;
      std::memcpy(&v, static_cast<const unsigned char*>(samples) + n * sizeof(T), sizeof(T));
      stored = static_cast<double>(v);
    });
    if (floating) {
      const std::string s(t);
      char* end = nullptr;
      const double value = text.type == ScalarType::Float32
                               ? static_cast<double>(std::strtof(s.c_str(), &end))
                               : std::strtod(s.c_str(), &end);
      if (end == s.c_str() || *end != '\0') refuse(n, s, "not a number");
      const bool same = value == stored || (std::isnan(value) && std::isnan(stored));
      if (!same) refuse(n, s, "read by the format's library as " + number_text(stored));
    } else {
      // A number in C's syntax (MetaIO reads 1e2 as 100; teem's 1 is caught by the comparison
      // below), integral and within the type's range.
      const std::string s(t);
      char* end = nullptr;
      const double value = std::strtod(s.c_str(), &end);
      if (end == s.c_str() || *end != '\0') refuse(n, s, "not a number");
      if (!std::isfinite(value) || std::floor(value) != value)
        refuse(n, s, "not an integer, as " + std::string(scalar_name(text.type)) + " samples are");
      const auto [lo, hi] = integer_range(text.type);
      if (value < lo || value > hi)
        refuse(n, s,
               "out of the " + std::string(scalar_name(text.type)) + " range (" + number_text(lo) +
                   " to " + number_text(hi) + ")");
      if (value != stored) refuse(n, s, "read by the format's library as " + number_text(stored));
    }
    ++n;
  }
}

}  // namespace isotile
