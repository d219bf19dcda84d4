// Writes the seeds of every fuzz target (fuzz_seeds.h) as starting corpora for the libFuzzer
// drivers: DIR/mesh, DIR/raw, DIR/nrrd, DIR/vdb and DIR/image, one file per seed.
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "tests/fuzz/fuzz_seeds.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 2;
  }
  namespace fs = std::filesystem;
  using isotile::fuzz::Seed;
  try {
    const std::pair<const char*, std::vector<Seed> (*)()> targets[] = {
        {"mesh", isotile::fuzz::mesh_seeds},
        {"raw", isotile::fuzz::raw_seeds},
        {"nrrd", isotile::fuzz::nrrd_seeds},
        {"vdb", isotile::fuzz::vdb_seeds},
        {"image", isotile::fuzz::image_seeds}};
    for (const auto& [name, seeds] : targets) {
      const fs::path dir = fs::path(argv[1]) / name;
      fs::create_directories(dir);
      std::size_t n = 0;
      for (const Seed& s : seeds()) {
        std::ofstream out(dir / s.name, std::ios::binary);
        out.write(reinterpret_cast<const char*>(s.bytes.data()),
                  static_cast<std::streamsize>(s.bytes.size()));
        if (!out) throw std::runtime_error("cannot write " + (dir / s.name).string());
        ++n;
      }
      std::printf("%s: %zu seeds in %s\n", name, n, dir.c_str());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}
