// libFuzzer driver for isotile::fuzz::fuzz_vdb (see fuzz_targets.h and docs/development.md).
#include <cstddef>
#include <cstdint>

#include "tests/fuzz/fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  isotile::fuzz::fuzz_vdb(data, size);
  return 0;
}
