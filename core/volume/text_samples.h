// Samples written as text (NRRD's ascii encoding, MetaImage's BinaryData = False), checked against
// what the format's library made of them. teem reads a token into an int and casts it to the
// sample type (300 in a uchar NRRD became 44, -5 became 251), stops at the first character that
// is not a digit (1e2 became 1, 2.7 became 2); MetaIO reads a double and casts it. A sample that
// is not the text's number is a wrong mesh with exit status 0: refused, naming the sample.
#pragma once

#include <cstdint>
#include <string>

#include "core/volume/volume.h"

namespace isotile {

struct TextSamples {
  std::string file;          // holding the text
  std::uint64_t offset = 0;  // where the samples' text starts in it
  ScalarType type = ScalarType::UInt8;
  std::int64_t count = 0;  // samples to check, x fastest
  // NRRD's ascii: a lone "," between values, and commas before or after a value, are passed
  // over (as teem passes them); MetaImage's text is whitespace only.
  bool commas = false;
  std::string what;  // "NRRD ascii", "MetaImage text": the message's name for the encoding
  // The index of the text's first sample in the volume: a NRRD's samples in several data files
  // are checked file by file.
  std::int64_t first = 0;
};

// Reads the text token by token and throws InputError, naming `file`, the sample's index and
// position and its token, where a token is not a number the type holds (integers: an optional
// sign and digits, within the type's range; floats: a whole number in C's syntax, nan and inf
// included, which check_finite refuses later), or where `samples` (the whole volume's, of `type`,
// as the library read them; the text holds `count` of them from `first`) holds another value.
// Fewer tokens than samples is left to the library.
void verify_text_samples(const TextSamples& text, const void* samples, const Index3& dims);

}  // namespace isotile
