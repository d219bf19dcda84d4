// Slice files named by a numbered pattern (slice_%03d.tif): the pattern checked and expanded
// without handing it to printf, where a %s or %n of the user's would read or write through a
// stray pointer. Header-only: the check before ITK reads (volume_io.cpp) and the ITK reader
// module (itk_reader.cpp, loaded at run time) expand it the same way.
#pragma once

#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <system_error>
#include <vector>

#include "core/errors.h"

namespace isotile {

// A pattern's parts: the text before and after its one integer conversion, and its width
// (zero-padded when `zeros`).
struct NumberedPattern {
  std::string before, after;
  int width = 0;
  bool zeros = false;

  std::string name(std::int64_t number) const {
    std::string digits = std::to_string(number);
    if (static_cast<int>(digits.size()) < width)
      digits.insert(0, static_cast<std::size_t>(width) - digits.size(), zeros ? '0' : ' ');
    return before + digits + after;
  }
};

// One conversion %d, %i or %u with an optional 0 flag and width (%d, %03d, %4i), and %% for a
// percent sign; anything else is an InputError naming the pattern.
inline NumberedPattern parse_numbered_pattern(const std::string& pattern) {
  NumberedPattern p;
  bool seen = false;
  std::string* text = &p.before;
  auto refuse = [&](const std::string& why) {
    throw InputError(pattern + ": not a slice pattern (" + why +
                     "); name the slice number with one %d, or %03d for zero-padded numbers, "
                     "and a percent sign with %%");
  };
  for (std::size_t i = 0; i < pattern.size(); ++i) {
    if (pattern[i] != '%') {
      text->push_back(pattern[i]);
      continue;
    }
    if (i + 1 < pattern.size() && pattern[i + 1] == '%') {
      text->push_back('%');
      ++i;
      continue;
    }
    std::size_t j = i + 1;
    if (j < pattern.size() && pattern[j] == '0') {
      p.zeros = true;
      ++j;
    }
    int width = 0;
    for (; j < pattern.size() && pattern[j] >= '0' && pattern[j] <= '9'; ++j) {
      width = width * 10 + (pattern[j] - '0');
      if (width > 64) refuse("a width over 64");
    }
    if (j >= pattern.size() || (pattern[j] != 'd' && pattern[j] != 'i' && pattern[j] != 'u'))
      refuse("'" + pattern.substr(i, j + 1 - i) + "' is not an integer conversion");
    if (seen) refuse("more than one conversion");
    seen = true;
    p.width = width;
    text = &p.after;
    i = j;
  }
  if (!seen) refuse("no conversion");
  return p;
}

// The files numbered from 0 on while they exist, or else from 1 on. A file with a higher number
// in the same folder means slices are missing: InputError naming the first missing one (a stack
// cut short at a gap would be a volume with its top cut off). IoError when no file matches.
inline std::vector<std::string> numbered_files(const std::string& pattern) {
  namespace fs = std::filesystem;
  const NumberedPattern p = parse_numbered_pattern(pattern);
  std::vector<std::string> out;
  std::error_code ec;
  std::int64_t first = 0;
  for (first = 0; first <= 1 && out.empty(); ++first)
    for (std::int64_t i = first; fs::is_regular_file(p.name(i), ec); ++i) out.push_back(p.name(i));
  if (out.empty()) throw IoError("cannot open " + pattern + ": no file matches the pattern");
  const std::int64_t last = first - 1 + static_cast<std::int64_t>(out.size()) - 1;
  // Other numbers in the folder: names of the pattern's form whose number is past the run.
  const fs::path folder = fs::path(p.before).parent_path();
  const std::string stem = fs::path(p.before).filename().string();
  std::set<std::int64_t> beyond;
  for (const auto& e : fs::directory_iterator(folder.empty() ? fs::path(".") : folder, ec)) {
    const std::string n = e.path().filename().string();
    if (n.size() <= stem.size() + p.after.size() || n.compare(0, stem.size(), stem) != 0 ||
        n.compare(n.size() - p.after.size(), p.after.size(), p.after) != 0)
      continue;
    const std::string digits = n.substr(stem.size(), n.size() - stem.size() - p.after.size());
    if (digits.size() > 18 || digits.find_first_not_of("0123456789 ") != std::string::npos ||
        digits.find_first_of("0123456789") == std::string::npos)
      continue;
    const std::int64_t number = std::stoll(digits);
    if (number > last && p.name(number) == (folder / n).string()) beyond.insert(number);
  }
  if (!beyond.empty())
    throw InputError(pattern + ": slice " + p.name(last + 1) + " is missing, but " +
                     std::to_string(beyond.size()) + " numbered after it exist (up to " +
                     p.name(*beyond.rbegin()) + "); a stack needs every slice");
  return out;
}

}  // namespace isotile
