// Seed inputs for the fuzz targets (fuzz_targets.h), built in code: small valid files written
// with the project's own mesh writers, zlib, teem's nrrdSave and OpenVDB's io::File, plus a few
// hand-written files for reader features the writers never produce, and a few files that must be
// rejected. Each seed is already in its target's input layout (selector byte first where the
// target has one).
//
// Used by the replay test, which mutates them, and by isotile_fuzz_write_seeds, which writes them
// out as starting corpora for the libFuzzer drivers. Throws std::runtime_error when a library
// fails to write a seed.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace isotile::fuzz {

struct Seed {
  std::string name;  // for messages and file names
  std::vector<std::uint8_t> bytes;
  bool readable = true;  // whether the reader must accept it (else throw Error)
};

std::vector<Seed> mesh_seeds();
std::vector<Seed> raw_seeds();
std::vector<Seed> nrrd_seeds();
std::vector<Seed> vdb_seeds();
// MRC maps written in code; NIfTI and MetaImage written by ITK (where the build has it).
std::vector<Seed> image_seeds();

// A structure-aware VDB input for fuzz_vdb, drawn from `seed`: one to three grids of random types,
// names, transforms, compression, active voxels, tiles and values (NaN, Inf and huge ones
// included), written by OpenVDB. Mutating the bytes of VDB files instead crashes or hangs OpenVDB
// itself (see docs/development.md, "Fuzzing"); these exercise read_vdb's own logic safely.
Seed random_vdb_seed(std::uint32_t seed);

}  // namespace isotile::fuzz
