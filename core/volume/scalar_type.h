// Scalar types of volume samples.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace isotile {

enum class ScalarType : std::uint8_t {
  Int8,
  UInt8,
  Int16,
  UInt16,
  Int32,
  UInt32,
  Float32,
  Float64
};
inline constexpr int kScalarTypeCount = 8;

// Bytes per sample.
std::size_t scalar_size(ScalarType type);
// Canonical lower-case name: "int8", "uint8", ..., "float32", "float64".
std::string_view scalar_name(ScalarType type);
// Accepts the canonical names and the aliases char/uchar/short/ushort/int/uint/float/double.
std::optional<ScalarType> parse_scalar_type(std::string_view name);
bool is_floating(ScalarType type);

// Calls f(T{}) with T the C++ type of `type`; returns what f returns.
template <class F>
decltype(auto) visit_scalar(ScalarType type, F&& f) {
  switch (type) {
    case ScalarType::Int8:
      return f(std::int8_t{});
    case ScalarType::UInt8:
      return f(std::uint8_t{});
    case ScalarType::Int16:
      return f(std::int16_t{});
    case ScalarType::UInt16:
      return f(std::uint16_t{});
    case ScalarType::Int32:
      return f(std::int32_t{});
    case ScalarType::UInt32:
      return f(std::uint32_t{});
    case ScalarType::Float32:
      return f(float{});
    case ScalarType::Float64:
      break;
  }
  return f(double{});
}

template <class T>
constexpr ScalarType scalar_type_of();
template <>
constexpr ScalarType scalar_type_of<std::int8_t>() {
  return ScalarType::Int8;
}
template <>
constexpr ScalarType scalar_type_of<std::uint8_t>() {
  return ScalarType::UInt8;
}
template <>
constexpr ScalarType scalar_type_of<std::int16_t>() {
  return ScalarType::Int16;
}
template <>
constexpr ScalarType scalar_type_of<std::uint16_t>() {
  return ScalarType::UInt16;
}
template <>
constexpr ScalarType scalar_type_of<std::int32_t>() {
  return ScalarType::Int32;
}
template <>
constexpr ScalarType scalar_type_of<std::uint32_t>() {
  return ScalarType::UInt32;
}
template <>
constexpr ScalarType scalar_type_of<float>() {
  return ScalarType::Float32;
}
template <>
constexpr ScalarType scalar_type_of<double>() {
  return ScalarType::Float64;
}

}  // namespace isotile
