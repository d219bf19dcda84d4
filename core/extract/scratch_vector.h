// Memory the extractors fill in full. In a one-shot run every large array is freshly mapped, and
// each 4 KiB page costs a fault on its first touch (about 1.5-2 us here: a third of a cold
// Marching Cubes extraction's own work on bonsai went to the mesh arrays' faults and zeroing).
//
// ScratchVector: a std::vector whose resize leaves new elements default-initialised (trivial
// types: uninitialised), for scratch tables (inside bits, per-row counts and offsets, mixed-cell
// masks) that a pass writes in full before anything reads them. A plain vector would zero them
// first: a serial memset that also takes every page fault on one thread, before the parallel
// pass writes the same bytes again; left uninitialised, the pages are first touched by the
// threads that fill them.
//
// reserve_huge: reserves a vector that is about to be resized and filled (the mesh's arrays, which
// stay plain std::vectors) and asks the kernel for transparent huge pages over the new block, so
// that zeroing it takes one fault per 2 MiB instead of per 4 KiB (8 MB of triangles: 3.5 ms ->
// 1.6 ms here). A hint only: where huge pages are off, or the system is not Linux, it is a plain
// reserve. Reserving on the calling thread also keeps the block in the calling thread's malloc
// arena when a worker thread then resizes it (an allocation made on a TBB worker lands in that
// thread's arena, which kept 0.6 MB more resident in bricked Dual Contouring).
//
// Internal to core/; not part of the library's interface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <utility>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace isotile::detail {

template <class T>
struct ScratchAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = ScratchAllocator<U>;
  };
  ScratchAllocator() = default;
  template <class U>
  ScratchAllocator(const ScratchAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

template <class T>
using ScratchVector = std::vector<T, ScratchAllocator<T>>;

template <class V>
void reserve_huge(V& v, std::size_t n) {
  v.reserve(n);
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr std::uintptr_t kHuge = std::uintptr_t{1} << 21;
  if (v.empty() && n * sizeof(typename V::value_type) >= 2 * kHuge) {
    // Only whole huge pages inside the block: the advice must not reach a neighbouring allocation.
    const auto begin = reinterpret_cast<std::uintptr_t>(v.data());
    const std::uintptr_t lo = (begin + kHuge - 1) & ~(kHuge - 1);
    const std::uintptr_t hi = (begin + n * sizeof(typename V::value_type)) & ~(kHuge - 1);
    if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
  }
#endif
}

}  // namespace isotile::detail
