#include "tiler/input_options.h"

#include <array>
#include <cmath>
#include <sstream>
#include <type_traits>

#include "core/errors.h"

namespace isotile {

namespace {

// "256,256,128" -> three numbers.
template <class T>
std::array<T, 3> parse_triple(const std::string& text, const std::string& what) {
  std::array<T, 3> out{};
  // Exactly three items between commas, each a whole number: a fourth, or an empty one after a
  // trailing comma, is an error, not dropped.
  std::size_t start = 0;
  for (int n = 0; n < 3; ++n) {
    const std::size_t comma = text.find(',', start);
    if ((n < 2) != (comma != std::string::npos)) start = std::string::npos;
    if (start == std::string::npos) break;
    const std::string item = text.substr(start, comma == std::string::npos ? comma : comma - start);
    std::size_t used = 0;
    try {
      if constexpr (std::is_integral_v<T>)
        out[n] = std::stoll(item, &used);
      else
        out[n] = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size()) {
      start = std::string::npos;
      break;
    }
    start = comma == std::string::npos ? text.size() : comma + 1;
  }
  if (start != text.size())
    throw InputError(what + " must be three comma-separated numbers, got '" + text + "'");
  return out;
}

}  // namespace

RawOptions parse_input_text(const InputText& text, const std::string& flag_prefix) {
  RawOptions o;
  if (!text.dims.empty()) o.dims = parse_triple<std::int64_t>(text.dims, flag_prefix + "dims");
  if (!text.type.empty()) {
    o.type = parse_scalar_type(text.type);
    if (!o.type)
      throw InputError("unknown " + flag_prefix + "type '" + text.type +
                       "' (expected int8, uint8, int16, uint16, int32, uint32, float32 or "
                       "float64)");
  }
  if (!text.spacing.empty()) {
    o.spacing = parse_triple<double>(text.spacing, flag_prefix + "spacing");
    // Zero flattens the mesh, a negative spacing turns it inside out, NaN poisons every vertex.
    for (double v : *o.spacing)
      if (!(std::isfinite(v) && v > 0))
        throw InputError(flag_prefix + "spacing must be three finite numbers above 0, got '" +
                         text.spacing + "'");
  }
  if (!text.origin.empty()) {
    o.origin = parse_triple<double>(text.origin, flag_prefix + "origin");
    for (double v : *o.origin)
      if (!std::isfinite(v))
        throw InputError(flag_prefix + "origin must be three finite numbers, got '" + text.origin +
                         "'");
  }
  if (!text.endian.empty() && text.endian != "little" && text.endian != "big")
    throw InputError(flag_prefix + "endian must be 'little' or 'big', got '" + text.endian + "'");
  o.endian = text.endian == "big" ? Endian::Big : Endian::Little;
  return o;
}

}  // namespace isotile
