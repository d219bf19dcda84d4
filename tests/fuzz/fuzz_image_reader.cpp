// libFuzzer driver for isotile::fuzz::fuzz_image (see fuzz_targets.h and docs/development.md).
#include <cstddef>
#include <cstdint>

#include "tests/fuzz/fuzz_targets.h"

extern "C" const char* __asan_default_options() {
  return "allocator_may_return_null=1";
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  isotile::fuzz::fuzz_image(data, size);
  return 0;
}
