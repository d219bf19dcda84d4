// The library's version, the one the CLI's --version prints and the CMake package's
// isotile_VERSION gives at configure time: a program linked against an installed isotile can say
// which one it runs.
#pragma once

#include <string_view>

namespace isotile {

// "MAJOR.MINOR.PATCH" (the project's version in CMakeLists.txt).
std::string_view version();

}  // namespace isotile
