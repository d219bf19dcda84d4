#include "core/volume/scalar_type.h"

#include <array>
#include <string>

#include "core/errors.h"

namespace isotile {

namespace {
struct TypeInfo {
  std::string_view name;
  std::size_t size;
  bool floating;
};
constexpr std::array<TypeInfo, kScalarTypeCount> kTypes = {{
    {"int8", 1, false},
    {"uint8", 1, false},
    {"int16", 2, false},
    {"uint16", 2, false},
    {"int32", 4, false},
    {"uint32", 4, false},
    {"float32", 4, true},
    {"float64", 8, true},
}};
}  // namespace

// A type outside the enum (a cast from a number) is an error, not a read past the table.
static const TypeInfo& type_entry(ScalarType type) {
  const int i = static_cast<int>(type);
  if (i < 0 || i >= kScalarTypeCount)
    throw InputError("unknown scalar type " + std::to_string(i) + " (ScalarType has " +
                     std::to_string(kScalarTypeCount) + ")");
  return kTypes[i];
}

std::size_t scalar_size(ScalarType type) {
  return type_entry(type).size;
}
std::string_view scalar_name(ScalarType type) {
  return type_entry(type).name;
}
bool is_floating(ScalarType type) {
  return type_entry(type).floating;
}

std::optional<ScalarType> parse_scalar_type(std::string_view name) {
  for (int i = 0; i < kScalarTypeCount; ++i)
    if (kTypes[i].name == name) return static_cast<ScalarType>(i);
  struct Alias {
    std::string_view name;
    ScalarType type;
  };
  static constexpr Alias kAliases[] = {
      {"char", ScalarType::Int8},     {"uchar", ScalarType::UInt8},   {"short", ScalarType::Int16},
      {"ushort", ScalarType::UInt16}, {"int", ScalarType::Int32},     {"uint", ScalarType::UInt32},
      {"float", ScalarType::Float32}, {"double", ScalarType::Float64}};
  for (const Alias& a : kAliases)
    if (a.name == name) return a.type;
  return std::nullopt;
}

}  // namespace isotile
