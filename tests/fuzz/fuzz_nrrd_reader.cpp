// libFuzzer driver for isotile::fuzz::fuzz_nrrd (see fuzz_targets.h and docs/development.md).
#include <cstddef>
#include <cstdint>

#include "tests/fuzz/fuzz_targets.h"

// teem allocates whatever a header asks for and copes with a null result, as glibc gives for
// impossible sizes; and it leaks its zlib and bzip2 state when compressed data turns out corrupt.
extern "C" const char* __asan_default_options() {
  return "allocator_may_return_null=1";
}
extern "C" const char* __lsan_default_suppressions() {
  return "leak:libteem.so\nleak:libz.so\nleak:libbz2.so\n";
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  isotile::fuzz::fuzz_nrrd(data, size);
  return 0;
}
