#include "core/version.h"

namespace isotile {

std::string_view version() {
  return ISOTILE_VERSION;  // set by core/CMakeLists.txt from the project's version
}

}  // namespace isotile
