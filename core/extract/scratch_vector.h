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
// reserve_on_caller: reserves a vector that is about to be resized and filled (the mesh's arrays,
// which stay plain std::vectors) on the calling thread, which keeps the block in the calling
// thread's malloc arena when a worker thread then resizes it (an allocation made on a TBB worker
// lands in that thread's arena, which kept 0.6 MB more resident in bricked Dual Contouring). It
// used to ask for transparent huge pages too (8 MB of triangles zeroed in 1.6 ms instead of 3.5),
// but on these virtual machines a fresh huge page costs more than 512 small ones (the host hands
// free 2 MiB blocks back and faults them in again): MC in core on a 4 GiB volume (181M triangles)
// took 7.4-7.5 s with the advice and 3.6-3.7 s without, while bonsai gained nothing measurable
// (16-18 ms either way).
//
// Internal to core/; not part of the library's interface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <utility>
#include <vector>

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
void reserve_on_caller(V& v, std::size_t n) {
  v.reserve(n);
}

}  // namespace isotile::detail
