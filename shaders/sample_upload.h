// The samples of a slab on the device as they are stored: 8- and 16-bit integers packed four and
// two to a 32-bit word, float32 as float, 32-bit integers as int or uint, float64 as double. The
// shaders widen each sample as they fetch it (sample_value() in mc_common.glsl), so no converted
// copy of the volume is made on the CPU, and the device reads exactly the CPU's values.
//
// The bytes go through a few pinned, persistently mapped staging buffers (glBufferStorage with
// GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT), kept for the context's life and reused by every
// slab and run of the process: rows are copied into one staging buffer while the device copies
// the previous one into the slab's device-local buffer (glCopyNamedBufferSubData); a fence per
// staging buffer says when it may be refilled. Call only inside a gl::Scope.
#pragma once

#include <glad/gl.h>

#include <cstdint>
#include <string>

#include "core/volume/volume.h"
#include "gl_program.h"

namespace isotile::gl {

class StageClock;

struct Samples {
  Buffer buffer;
  std::string defines;      // the sample type's defines (sample_defines())
  std::uint64_t bytes = 0;  // bytes of samples uploaded (before the padding to a whole word)
};

// Uploads the samples of `view` in the global box `region` (inside view.box), x fastest. With a
// clock, the upload is timed from the first byte handed to GL to the last one resident.
Samples upload_samples(const VolumeView& view, const Box3& region, StageClock* clock = nullptr);

// The defines of upload_samples() for samples of `type`: SAMPLE_<TYPE> (the buffer's layout and
// the widening fetch) and, for the types a float holds exactly (8- and 16-bit integers, float32),
// SAMPLE_IS_FLOAT (the inside test in float).
std::string sample_defines(ScalarType type);

// Every scalar type, in the order the variant table lists them.
inline constexpr ScalarType kSampleTypes[] = {
    ScalarType::Int8,  ScalarType::UInt8,  ScalarType::Int16,   ScalarType::UInt16,
    ScalarType::Int32, ScalarType::UInt32, ScalarType::Float32, ScalarType::Float64};

// The staging buffers: kStagingBuffers of at most kDefaultStagingBytes each (unless a test sets
// another size), no larger than the largest upload so far needs (mapped_bytes_for()), created on
// first use and made again larger when an upload needs more.
inline constexpr std::size_t kDefaultStagingBytes = std::size_t{32} << 20;
inline constexpr int kStagingBuffers = 3;
// For tests: staging buffers of at most `bytes` each (at least one row of a slab must fit) from the
// next upload on; the current ones are released (inside a gl::Scope).
void set_staging_bytes(std::size_t bytes);

// Makes the staging buffers that an upload of `bytes` fills (as upload_samples() would when it
// gets there), so that they can be made ahead of it (prepare_backend(), gl_backends.cpp).
void reserve_staging(std::size_t bytes);

// How many staging buffers were created in this process so far (reuse is checked by the tests),
// and the bytes of those held now.
int staging_buffers_created();
std::size_t staging_bytes_held();

}  // namespace isotile::gl
