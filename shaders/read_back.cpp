#include "read_back.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <optional>

#include "gl_context.h"
#include "gl_program.h"

namespace isotile::gl {

namespace {

// The pinned buffers, mapped once and kept until shutdown(). A buffer's fence marks the device
// copy into it that the CPU has not yet waited for.
std::array<MappedBuffer, kReadBackBuffers>& pinned() {
  static std::array<MappedBuffer, kReadBackBuffers> buffers;
  return buffers;
}
int& created_count() {
  static int n = 0;
  return n;
}
// Set by set_read_back_bytes(); unset, the device decides (piece_size()).
std::optional<std::size_t>& forced_size() {
  static std::optional<std::size_t> bytes;
  return bytes;
}
// On a software rasteriser a buffer is host memory already: the pinned buffers would add a copy
// (llvmpipe: 3.9-7.5 GB/s through them against 7.2-13.3 GB/s straight, bench_backends' table).
std::size_t piece_size() {
  if (forced_size()) return *forced_size();
  return device().software ? 0 : kDefaultReadBackBytes;
}

void release_read_back() {
  for (MappedBuffer& b : pinned()) b.release();
}

// Buffer `i`, of at least `bytes` (made, or made again larger, when needed).
MappedBuffer& pinned_buffer(int i, std::size_t bytes) {
  MappedBuffer& b = pinned()[static_cast<std::size_t>(i)];
  at_shutdown(release_read_back);
  // Read access: the device writes it by DMA, the CPU reads it cached.
  if (b.ensure(bytes, GL_MAP_READ_BIT, "a buffer to read the mesh back through")) ++created_count();
  return b;
}

// One thread copies a few GB/s; the mesh's arrays are tens to hundreds of MB.
void parallel_copy(std::byte* dst, const std::byte* src, std::size_t bytes) {
  constexpr std::size_t kBlock = std::size_t{1} << 20;
  const std::size_t blocks = (bytes + kBlock - 1) / kBlock;
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t i) {
    const std::size_t begin = i * kBlock;
    std::memcpy(dst + begin, src + begin, std::min(kBlock, bytes - begin));
  });
}

}  // namespace

int read_back_buffers_created() {
  return created_count();
}

std::size_t read_back_bytes_held() {
  return bytes_held(pinned());
}

void set_read_back_bytes(std::size_t bytes) {
  release_read_back();
  forced_size() = bytes;
}

void use_default_read_back() {
  release_read_back();
  forced_size().reset();
}

void read_back(GLuint id, std::size_t offset, std::size_t bytes, void* out) {
  if (bytes == 0) return;
  // Pieces of at most piece_size(), in buffers no larger than the read needs.
  const std::size_t cap = piece_size();
  const std::size_t piece = cap == 0 ? 0 : mapped_bytes_for(bytes, cap);
  if (piece == 0 || bytes < kPinnedReadMinBytes) {
    glGetNamedBufferSubData(id, static_cast<GLintptr>(offset), static_cast<GLsizeiptr>(bytes), out);
    check("reading a buffer back");
    return;
  }
  const std::size_t pieces = (bytes + piece - 1) / piece;
  auto length = [&](std::size_t p) { return std::min(piece, bytes - p * piece); };
  auto issue = [&](std::size_t p) {
    MappedBuffer& b = pinned_buffer(static_cast<int>(p % kReadBackBuffers), piece);
    b.wait();  // only after an earlier read was cut short by an error
    glCopyNamedBufferSubData(id, b.id, static_cast<GLintptr>(offset + p * piece), 0,
                             static_cast<GLsizeiptr>(length(p)));
    b.fence_commands();
  };
  // Every buffer busy from the start; each piece copied out frees its buffer for the next one.
  for (std::size_t p = 0; p < std::min<std::size_t>(pieces, kReadBackBuffers); ++p) issue(p);
  check("copying a buffer for reading back");
  for (std::size_t p = 0; p < pieces; ++p) {
    MappedBuffer& b = pinned()[p % kReadBackBuffers];
    b.wait();  // landed; with a coherent mapping its bytes are visible to the CPU
    parallel_copy(static_cast<std::byte*>(out) + p * piece, b.mapped, length(p));
    if (p + kReadBackBuffers < pieces) issue(p + kReadBackBuffers);
  }
  check("reading a buffer back");
}

}  // namespace isotile::gl
