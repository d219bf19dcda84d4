// Error types of the isotile library.
//
// Internal preconditions use assert(). Everything a user can cause (a bad file, a bad option, a
// volume too large to index) is reported by throwing one of these, with a message that names the
// problem and, where possible, what to do about it. The CLI prints what() on one line.
#pragma once

#include <charconv>
#include <stdexcept>
#include <string>

namespace isotile {

// Base of all isotile errors.
struct Error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Bad input: a malformed or inconsistent file, an invalid option value.
struct InputError : Error {
  using Error::Error;
};

// The operating system refused a read or a write (missing file, permission, full disk).
struct IoError : Error {
  using Error::Error;
};

// The request is valid but exceeds what this build can represent (e.g. > 2^32 vertices in an
// in-memory mesh).
struct CapacityError : Error {
  using Error::Error;
};

// A number in a message: the shortest text that reads back as the same double (std::to_string's
// six decimals show -1e-9 as "-0.000000" and 0.6 as "0.600000").
inline std::string number_text(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

}  // namespace isotile
