// Software prefetch for the fill passes. Internal to core/.
#pragma once

#include <cstddef>

namespace isotile::detail {

// How many point rows ahead a fill pass fetches the samples it will read first (2 to 8 gave the
// same times; see marching_cubes.cpp).
inline constexpr int kPrefetchRows = 4;

// Asks the CPU to bring [p, p + bytes) into cache ahead of use. A prefetch never faults, so a span
// that runs past the samples only wastes a hint.
inline void prefetch_bytes(const void* p, std::size_t bytes) {
  const char* c = static_cast<const char*>(p);
  for (std::size_t b = 0; b < bytes; b += 64) __builtin_prefetch(c + b);
}

}  // namespace isotile::detail
