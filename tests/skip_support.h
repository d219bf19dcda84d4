// Skips that cannot hide a missing dependency: a test that cannot run says why with ISOTILE_SKIP
// and the kind of thing it lacks; where the run demands that kind (ISOTILE_STRICT_SKIPS, a
// comma-separated list of kind names or "all", set by .ci/run), the skip is a failure instead, so
// a suite cannot go green by skipping what it was meant to test.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <sstream>
#include <string>

namespace isotile::testing {

enum class SkipKind { Gl, Osmesa, SharedData, Meshlab, Mpi, Itk, Glslang };

inline const char* skip_kind_name(SkipKind k) {
  switch (k) {
    case SkipKind::Gl:
      return "gl";
    case SkipKind::Osmesa:
      return "osmesa";
    case SkipKind::SharedData:
      return "shared-data";
    case SkipKind::Meshlab:
      return "meshlab";
    case SkipKind::Mpi:
      return "mpi";
    case SkipKind::Itk:
      return "itk";
    case SkipKind::Glslang:
      return "glslang";
  }
  return "?";
}

inline bool skip_is_failure(SkipKind k) {
  const char* env = std::getenv("ISOTILE_STRICT_SKIPS");
  if (!env) return false;
  std::stringstream list(env);
  for (std::string item; std::getline(list, item, ',');)
    if (item == "all" || item == skip_kind_name(k)) return true;
  return false;
}

}  // namespace isotile::testing

// Skips the current test with `message` (stream syntax), or fails it where the run demands
// `kind` (a SkipKind enumerator's name).
#define ISOTILE_SKIP(kind, message)                                                    \
  do {                                                                                 \
    std::ostringstream isotile_why_;                                                   \
    isotile_why_ << message;                                                           \
    if (::isotile::testing::skip_is_failure(::isotile::testing::SkipKind::kind))       \
      FAIL() << "cannot run ("                                                         \
             << ::isotile::testing::skip_kind_name(::isotile::testing::SkipKind::kind) \
             << " is required by ISOTILE_STRICT_SKIPS): " << isotile_why_.str();       \
    GTEST_SKIP() << isotile_why_.str();                                                \
  } while (0)
