// A library message in a front end's own terms. The library's messages name the CLI's options
// (`--dc-solver applies to --method dc only`); the MeshLab plugin shows its dialog's field labels
// and the Python module its keywords instead, each with its own table.
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <utility>

namespace isotile {

// `message` with each option of `terms` (CLI spelling -> the front end's), longest first, replaced
// where it stands as a word of the text: after a blank, '(', ',' or a quote and before a
// non-name character; not inside a path ("/data/--type/") or a command quoted in backticks
// (`isotile quality --check-intersections`), which must stay as they are.
std::string rename_options(std::string message,
                           std::span<const std::pair<std::string_view, std::string_view>> terms);

}  // namespace isotile
