// What users type to describe an input (the CLI's --dims/--type/--spacing/--origin/--endian, the
// MeshLab filter's fields of the same names), turned into the library's RawOptions. Shared so
// that both front ends accept the same text and say the same thing about bad text.
#pragma once

#include <string>

#include "core/volume/volume_io.h"

namespace isotile {

struct InputText {
  std::string dims;     // "256,256,128"
  std::string type;     // "uint16"
  std::string spacing;  // "0.5,0.5,1"
  std::string origin;   // "0,0,-10"
  std::string endian;   // "little" or "big"
};

// Empty fields stay unset (the file's name or header decides). Throws InputError naming the
// option (`flag_prefix` + name, e.g. "--dims" or "dims") and the text when a field is malformed.
RawOptions parse_input_text(const InputText& text, const std::string& flag_prefix = "--");

}  // namespace isotile
