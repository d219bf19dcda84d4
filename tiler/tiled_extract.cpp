#include "tiler/tiled_extract.h"

#include <tbb/parallel_pipeline.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "core/progress.h"
#include "tiler/brick_extraction.h"
#include "tiler/source_histogram.h"
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
    // No cells (a volume one sample thick), so no face.
    if (!options.allow_empty) {
      throw_no_surface(source, options.memory, options.extract.iso);
    }
    write_mesh(Mesh{}, output, {.format = options.format, .ascii = false, .write_normals = false});
    return result;
  }
  bricks.set_overlap(options.memory >= options.overlap_min_memory);
  result.plan = bricks.plan();
  result.backend = bricks.extract_options().backend;
  const std::int64_t total = result.plan.total();
  const std::size_t in_flight = bricks.overlap() ? 2 : 1;

  // Pass 1: count. With overlap, two bricks in flight: the next one is read while this one is
  // counted.
  auto t0 = Clock::now();
  source.rewind();
  {
    std::vector<char> buffers[2];
    std::int64_t next = 0;
    struct Read {
      std::int64_t brick;
      VolumeView view;
    };
    tbb::parallel_pipeline(
        in_flight,
        tbb::make_filter<
            void, Read>(tbb::filter_mode::serial_in_order, [&](tbb::flow_control& fc) -> Read {
          if (next == total) {
            fc.stop();
            return {};
          }
          const std::int64_t b = next++;
          // A buffer is free again once the brick two before is done.
          return {b, bricks.read_for_count(b, buffers[static_cast<std::size_t>(b) % in_flight])};
        }) & tbb::make_filter<Read, void>(tbb::filter_mode::serial_in_order, [&](const Read& r) {
          progress_check(options.progress);
          bricks.count(r.brick, r.view);
          // Through a child: a brick done, without disturbing another brick's report.
          if (options.progress) Progress(*options.progress, Stage::Count, r.brick, total).finish();
        }));
  }
  bricks.scan(result);
  result.seconds_count = since(t0);
  if (result.faces == 0 && !options.allow_empty) {
    throw_no_surface(source, options.memory, options.extract.iso);
  }

  AtomicFile file(output, AtomicFile::Writes::Positioned);
  const std::string header = bricks.header();
  file.write(header.data(), header.size());

  // Pass 2: read, extract and write, a part (a brick, or a z-slice of one) at a time; with
  // overlap, the next part is read and the previous one written meanwhile.
  t0 = Clock::now();
  source.rewind();
  QualityAccumulator quality;
  const WriteAt write = [&](std::uint64_t offset, const char* data, std::size_t n) {
    file.write_at(offset, data, n);
  };
  {
    struct Part {
      std::int64_t brick;
      bool last;  // of its brick
      Box3 cells;
    };
    std::vector<Part> parts;
    for (std::int64_t b = 0; b < total; ++b) {
      const std::vector<Box3> cut = bricks.parts(b, result);
      for (std::size_t i = 0; i < cut.size(); ++i)
        parts.push_back({b, i + 1 == cut.size(), cut[i]});
    }
    std::vector<char> buffers[2];
    std::size_t next = 0;
    struct Read {
      const Part* part;
      VolumeView view;
    };
    struct Done {
      const Part* part;
      std::shared_ptr<BrickRecords> records;
    };
    tbb::parallel_pipeline(
        in_flight,
        tbb::make_filter<void, Read>(
            tbb::filter_mode::serial_in_order,
            [&](tbb::flow_control& fc) -> Read {
              if (next == parts.size()) {
                fc.stop();
                return {};
              }
              const std::size_t i = next++;
              return {&parts[i], bricks.read_part(parts[i].cells, buffers[i % in_flight])};
            }) &
            tbb::make_filter<Read, Done>(
                tbb::filter_mode::serial_in_order,
                [&](const Read& r) -> Done {
                  // The core extraction reports within its brick (core/progress.h, Nesting)
                  // while the writer below finishes the brick before.
                  ChildProgress child(options.progress, Stage::Extract, r.part->brick, total);
                  return {r.part, std::make_shared<BrickRecords>(bricks.extract_part(
                                      r.part->cells, r.view, quality, child.get()))};
                }) &
            tbb::make_filter<Done, void>(tbb::filter_mode::serial_in_order, [&](const Done& d) {
              bricks.write(*d.records, write);
              if (d.part->last && options.progress)
                Progress(*options.progress, Stage::Extract, d.part->brick, total).finish();
            }));
  }
  result.seconds_extract = since(t0);
  result.stages = bricks.stages();
  result.gpu = bricks.gpu();
  if (bricks.written_faces() != result.faces)
    throw Error("tiled extraction wrote " + std::to_string(bricks.written_faces()) + " faces of " +
                std::to_string(result.faces) + " counted");
  source.check_unchanged();
  file.commit();
  if (options.quality) result.quality = quality.stats();
  return result;
}

// What run_pipeline() checks before it calls the tiler, checked again for the library's callers
// (a NaN spacing wrote NaN positions, a NaN isovalue an empty mesh, a simplify of 1.5 or NaN no
// simplification, and binary PLY went into a file named .stl, all without a word).
void check_tiled_input(const VolumeSource& source, const TiledOptions& options,
                       const std::filesystem::path& output) {
  check_grid_geometry(source.dims, source.spacing, source.origin, source.world, "the volume");
  if (!std::isfinite(options.extract.iso))
    throw InputError("--iso must be a finite number, got " + number_text(options.extract.iso));
  if (!(options.simplify > 0 && options.simplify <= 1))
    throw InputError("simplify must be in (0, 1] (1: off), got " + number_text(options.simplify));
  std::optional<MeshFormat> named;
  try {
    named = mesh_format_from_path(output);
  } catch (const InputError&) {
    // No mesh extension (a device, a name of the caller's): the options say.
  }
  if (named && *named != options.format)
    throw InputError(output.string() + ": its extension names another format than " +
                     (options.format == MeshFormat::Stl ? "STL" : "PLY") +
                     ", which TiledOptions::format asks for");
}

}  // namespace

TiledResult extract_tiled(VolumeSource& source, const TiledOptions& options,
                          const std::filesystem::path& output) {
  check_tiled_input(source, options, output);
  // Before the first pass: the streamed writer places each brick's records at their offsets
  // (positioned writes); the simplifying one writes its file front to back at the end.
  check_output(output, options.simplify >= 1);
  try {
    if (options.simplify < 1) return extract_tiled_simplified(source, options, output);
    return run(source, options, output);
  } catch (const Cancelled&) {
    throw;
  } catch (const Error& e) {
    // A changed input breaks the passes' agreement ("brick contract broken", a short read): that
    // is the error to give first, with the one that stopped the run.
    try {
      source.check_unchanged();
    } catch (const InputError& changed) {
      // Where the run stopped at this very finding (a brick's read checks too), it is said once.
      if (std::string_view(e.what()).find(changed.what()) != std::string_view::npos) throw;
      throw InputError(std::string(changed.what()) + " (the run stopped at: " + e.what() + ")");
    }
    throw;
  }
}

}  // namespace isotile
