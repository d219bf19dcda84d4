#include "sample_upload.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstring>

#include "core/errors.h"
#include "gl_context.h"
#include "stage_clock.h"

namespace isotile::gl {

namespace {

// The pinned staging buffers, mapped once and kept until shutdown(). A buffer's fence marks the
// device copy that still reads it.
std::array<MappedBuffer, kStagingBuffers>& staging() {
  static std::array<MappedBuffer, kStagingBuffers> buffers;
  return buffers;
}
int& created_count() {
  static int n = 0;
  return n;
}
std::size_t& staging_size() {
  static std::size_t bytes = kDefaultStagingBytes;
  return bytes;
}

void release_staging() {
  for (MappedBuffer& s : staging()) s.release();
}

// Buffer `i`, of at least `bytes` (made, or made again larger, when needed).
MappedBuffer& staging_buffer(int i, std::size_t bytes) {
  MappedBuffer& s = staging()[static_cast<std::size_t>(i)];
  at_shutdown(release_staging);
  if (s.ensure(bytes, GL_MAP_WRITE_BIT, "a staging buffer for the samples")) ++created_count();
  return s;
}

}  // namespace

int staging_buffers_created() {
  return created_count();
}

std::size_t staging_bytes_held() {
  return bytes_held(staging());
}

void set_staging_bytes(std::size_t bytes) {
  release_staging();
  staging_size() = std::max<std::size_t>(bytes, 4);
}

void reserve_staging(std::size_t bytes) {
  if (bytes == 0) return;
  const std::size_t chunk = mapped_bytes_for(bytes, staging_size());
  const std::size_t chunks = (bytes + chunk - 1) / chunk;
  for (std::size_t i = 0; i < std::min<std::size_t>(chunks, kStagingBuffers); ++i)
    staging_buffer(static_cast<int>(i), chunk);
}

std::string sample_defines(ScalarType type) {
  switch (type) {
    case ScalarType::Int8:
      return "#define SAMPLE_I8\n#define SAMPLE_IS_FLOAT\n";
    case ScalarType::UInt8:
      return "#define SAMPLE_U8\n#define SAMPLE_IS_FLOAT\n";
    case ScalarType::Int16:
      return "#define SAMPLE_I16\n#define SAMPLE_IS_FLOAT\n";
    case ScalarType::UInt16:
      return "#define SAMPLE_U16\n#define SAMPLE_IS_FLOAT\n";
    case ScalarType::Int32:
      return "#define SAMPLE_I32\n";
    case ScalarType::UInt32:
      return "#define SAMPLE_U32\n";
    case ScalarType::Float32:
      return "#define SAMPLE_F32\n#define SAMPLE_IS_FLOAT\n";
    case ScalarType::Float64:
      return "#define SAMPLE_F64\n";
  }
  return {};
}

Samples upload_samples(const VolumeView& view, const Box3& region, StageClock* clock) {
  Samples out;
  const std::size_t size = scalar_size(view.type);
  const Index3 d = {region.extent(0), region.extent(1), region.extent(2)};
  const std::size_t row_bytes = static_cast<std::size_t>(d[0]) * size;
  const std::int64_t rows = d[1] * d[2];
  out.bytes = row_bytes * static_cast<std::size_t>(rows);
  out.defines = sample_defines(view.type);
  // Whole 32-bit words: the shaders read 8- and 16-bit samples a word at a time.
  out.buffer = Buffer((out.bytes + 3) / 4 * 4);
  if (out.bytes == 0) return out;
  // Chunks of at most staging_size(), in buffers no larger than the samples need.
  const std::size_t chunk_bytes = mapped_bytes_for(out.bytes, staging_size());
  if (row_bytes > chunk_bytes)
    throw CapacityError("one row of " + std::to_string(d[0]) +
                        " samples exceeds the GL staging buffer");
  const std::int64_t rows_per_chunk = static_cast<std::int64_t>(chunk_bytes / row_bytes);
  const auto* src = static_cast<const std::byte*>(view.data);
  const std::int64_t i0 = region.lo[0] - view.box.lo[0];
  const bool contiguous_rows = view.strides[0] == 1;
  StageClock::Mark handed{};
  int next = 0;
  for (std::int64_t first = 0; first < rows; first += rows_per_chunk) {
    const std::int64_t n = std::min(rows_per_chunk, rows - first);
    MappedBuffer& s = staging_buffer(next, chunk_bytes);
    next = (next + 1) % kStagingBuffers;
    s.wait();  // until the device no longer reads it
    if (clock && first == 0) handed = StageClock::cpu_mark();
    // Copy whole rows as stored; the widening is the shaders'.
    tbb::parallel_for(std::int64_t{0}, n, [&](std::int64_t r) {
      const std::int64_t row = first + r;
      const std::int64_t j = region.lo[1] - view.box.lo[1] + row % d[1];
      const std::int64_t k = region.lo[2] - view.box.lo[2] + row / d[1];
      std::byte* dst = s.mapped + static_cast<std::size_t>(r) * row_bytes;
      if (contiguous_rows) {
        std::memcpy(dst, src + static_cast<std::size_t>(view.offset(i0, j, k)) * size, row_bytes);
      } else {
        for (std::int64_t i = 0; i < d[0]; ++i)
          std::memcpy(dst + static_cast<std::size_t>(i) * size,
                      src + static_cast<std::size_t>(view.offset(i0 + i, j, k)) * size, size);
      }
    });
    // Coherent mapping: the writes are visible to the copy without a flush.
    glCopyNamedBufferSubData(s.id, out.buffer.id(), 0,
                             static_cast<GLintptr>(static_cast<std::size_t>(first) * row_bytes),
                             static_cast<GLsizeiptr>(static_cast<std::size_t>(n) * row_bytes));
    s.fence_commands();
    submit();  // the device copies this chunk while the CPU fills the next buffer
  }
  check("uploading the samples");
  if (clock) {
    clock->add(GlStage::Upload, handed, clock->device_mark());
    clock->add_upload_bytes(out.bytes);
  }
  return out;
}

}  // namespace isotile::gl
