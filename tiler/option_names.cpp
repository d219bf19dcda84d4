#include "tiler/option_names.h"

#include <algorithm>
#include <cctype>
#include <cstddef>

namespace isotile {

std::string rename_options(std::string message,
                           std::span<const std::pair<std::string_view, std::string_view>> terms) {
  const auto quoted = [&](std::size_t at) {
    return std::count(message.begin(), message.begin() + static_cast<std::ptrdiff_t>(at), '`') %
               2 ==
           1;
  };
  for (const auto& [flag, name] : terms)
    for (std::size_t at = 0; (at = message.find(flag, at)) != std::string::npos;) {
      const std::size_t end = at + flag.size();
      const bool word_start =
          at == 0 || std::string_view(" (,'\"").find(message[at - 1]) != std::string_view::npos;
      const bool word_end =
          end == message.size() || !(std::isalnum(static_cast<unsigned char>(message[end])) ||
                                     message[end] == '-' || message[end] == '_');
      if (!word_start || !word_end || quoted(at)) {
        at = end;
        continue;
      }
      message.replace(at, flag.size(), name);
      at += name.size();
    }
  return message;
}

}  // namespace isotile
