#include "tiler/tiled_extract.h"

#include <chrono>
#include <string>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "tiler/brick_extraction.h"
#include "tiler/tiled_simplify.h"

namespace isotile {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

TiledResult run(VolumeSource& source, const TiledOptions& options,
                const std::filesystem::path& output) {
  TiledResult result;
  BrickExtraction bricks(source, options);
  if (bricks.empty_volume()) {
    write_mesh(Mesh{}, output, {.format = options.format, .ascii = false, .write_normals = false});
    return result;
  }
  result.plan = bricks.plan();
  result.backend = bricks.extract_options().backend;
  const std::int64_t total = result.plan.total();

  // Pass 1: count.
  auto t0 = Clock::now();
  source.rewind();
  for (std::int64_t b = 0; b < total; ++b) {
    bricks.count(b);
    if (options.progress) options.progress("count", b + 1, total);
  }
  bricks.scan(result);
  result.seconds_count = since(t0);

  AtomicFile file(output);
  const std::string header = bricks.header();
  file.write(header.data(), header.size());

  // Pass 2: extract and write.
  t0 = Clock::now();
  source.rewind();
  QualityAccumulator quality;
  const WriteAt write = [&](std::uint64_t offset, const char* data, std::size_t n) {
    file.write_at(offset, data, n);
  };
  for (std::int64_t b = 0; b < total; ++b) {
    bricks.extract(b, write, quality, result);
    if (options.progress) options.progress("extract", b + 1, total);
  }
  result.seconds_extract = since(t0);
  if (bricks.written_faces() != result.faces)
    throw Error("tiled extraction wrote " + std::to_string(bricks.written_faces()) + " faces of " +
                std::to_string(result.faces) + " counted");
  file.commit();
  if (options.quality) result.quality = quality.stats();
  return result;
}

}  // namespace

TiledResult extract_tiled(VolumeSource& source, const TiledOptions& options,
                          const std::filesystem::path& output) {
  if (options.simplify < 1) return extract_tiled_simplified(source, options, output);
  return run(source, options, output);
}

}  // namespace isotile
