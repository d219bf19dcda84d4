// Fuzz targets for the file readers, shared by the libFuzzer drivers (fuzz_*_reader.cpp, Clang
// with ISOTILE_FUZZ=ON) and the deterministic replay test (test_fuzz_replay.cpp, every build).
//
// Each target writes the input to a file in a directory private to the process (work_dir()),
// calls one reader and checks what it returns. A reader may return or throw isotile::Error; the
// targets catch exactly that. Anything else leaves the target: another exception, or
// InvariantViolation when the returned mesh or volume is inconsistent (a face index out of range,
// a byte size other than dims * sample size, a NaN in a floating-point volume, ...). A crash or a
// sanitizer report leaves the input file behind in work_dir() for reproduction.
//
// Input layout (the first byte picks a variant; the rest is the file):
//   fuzz_mesh  byte 0: bits 0-1 the format (.ply, .obj, .off, .stl), bit 2 an upper-case
//              extension; bytes 1..: the file.
//   fuzz_raw   byte 0: bit 0 gzip (.raw.gz), bit 1 big-endian, bits 2-4 the ScalarType, bits 5-7
//              the layout (raw_layout()); bytes 1..: the file (gzip data when bit 0 is set).
//   fuzz_nrrd  byte 0: bit 0 detached header; bytes 1..: an attached .nrrd, or, when detached, a
//              .nhdr header up to and including the first "\n\n" followed by the bytes of its
//              data file, which is written as "data.bin" beside it ("data file: data.bin").
//   fuzz_vdb   all bytes: the .vdb file.
//   fuzz_image byte 0: bits 0-2 the format (0 .mrc, 1 .nii, 2 .mha, 3 .map, 4 .dcm, 5 .tif,
//              6 .nii.gz, 7 .map.gz); bytes 1..: the file, read through read_volume (isotile's
//              MRC reader; ITK's NIfTI, MetaImage and TIFF readers and GDCM behind isotile's
//              header checks).
//
// Each target returns 0 when the reader returned a value that passed the checks and 1 when it
// threw isotile::Error (the libFuzzer drivers ignore this and return 0). Not thread-safe: one
// call at a time per process.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

#include "core/volume/volume.h"

namespace isotile::fuzz {

// A reader returned something it must not have.
struct InvariantViolation : std::logic_error {
  using std::logic_error::logic_error;
};

int fuzz_mesh(const std::uint8_t* data, std::size_t size);
int fuzz_raw(const std::uint8_t* data, std::size_t size);
int fuzz_nrrd(const std::uint8_t* data, std::size_t size);
int fuzz_vdb(const std::uint8_t* data, std::size_t size);
int fuzz_image(const std::uint8_t* data, std::size_t size);

// What fuzz_raw passes to read_raw for layout `index` (0-7, bits 5-7 of the first byte) and
// sample type `type`: the file name, and the dims and type given as options (absent where the
// name supplies them).
struct RawLayout {
  std::string file_name;
  std::optional<Index3> option_dims;
  std::optional<ScalarType> option_type;
  Index3 dims;  // what the volume must have
};
RawLayout raw_layout(int index, ScalarType type, bool gzip);

// The private directory the targets write to: <temp>/isotile_fuzz_<pid>. Created on first use;
// removed at normal process exit.
const std::filesystem::path& work_dir();

}  // namespace isotile::fuzz
