// Device buffers read back into host memory through pinned staging: the way out, as
// sample_upload.h is the way in.
//
// glGetNamedBufferSubData writes into the caller's pageable memory, which a driver cannot hand to
// its DMA engine: it copies through buffers of its own. On the NVIDIA H200 the same route inward
// (glNamedBufferStorage or glNamedBufferSubData from pageable memory) ran at 1.4-1.8 GB/s, against
// 37-50 GB/s through a persistently mapped client-storage buffer (docs/gl.md, "The mesh's way
// out"); the mesh's arrays, read back after the vertex and face passes, are as large as the
// samples on most volumes.
//
// A read of at least kPinnedReadMinBytes is cut into pieces: the device copies each piece
// (glCopyNamedBufferSubData) into one of a few pinned, persistently mapped buffers
// (GL_MAP_READ_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT | GL_CLIENT_STORAGE_BIT, kept
// for the context's life and reused by every read of the process), a fence per piece says when
// it has landed, and the CPU threads copy it out while the device copies the next ones. Smaller
// reads (a pass's totals) go straight through glGetNamedBufferSubData. Call only inside a
// gl::Scope, after the barrier that makes the writes to be read visible to buffer copies
// (dispatch() issues it).
#pragma once

#include <glad/gl.h>

#include <cstddef>

namespace isotile::gl {

// Reads `bytes` from `offset` of buffer `id` into `out` (gl::Buffer::read() calls it).
void read_back(GLuint id, std::size_t offset, std::size_t bytes, void* out);

// The pinned buffers: kReadBackBuffers of at most kDefaultReadBackBytes each, no larger than the
// largest read so far needs (mapped_bytes_for()), created on first use and made again larger
// when a read needs more, on a hardware device; reads below kPinnedReadMinBytes do not use them. A
// software rasteriser (DeviceInfo::software) reads straight through glGetNamedBufferSubData, which
// is one memcpy there.
inline constexpr std::size_t kDefaultReadBackBytes = std::size_t{8} << 20;
inline constexpr int kReadBackBuffers = 3;
inline constexpr std::size_t kPinnedReadMinBytes = std::size_t{64} << 10;

// For tests and benchmarks, on any device: pinned buffers (and pieces) of at most `bytes` each from
// the next read on, or with 0 every read straight through glGetNamedBufferSubData; then
// use_default_read_back() returns to the device's choice. Both release the current buffers
// (inside a gl::Scope).
void set_read_back_bytes(std::size_t bytes);
void use_default_read_back();

// How many pinned read-back buffers were created in this process so far, and the bytes of those
// held now.
int read_back_buffers_created();
std::size_t read_back_bytes_held();

}  // namespace isotile::gl
