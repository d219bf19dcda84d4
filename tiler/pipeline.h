// One extraction run, for every way in (the isotile CLI, the Python module, the MeshLab plugin):
// open the input, choose the isovalue, extract in core or brick by brick within a memory budget,
// check for an empty surface, simplify, write, measure, and build the statistics object that
// `isotile extract --stats` prints (docs/cli.md). Front ends only turn their arguments into a
// PipelineInput and PipelineOptions and present the result; the checks, the messages and the
// numbers are the library's.
//
//   PipelineInput in;
//   in.path = "ct.nrrd";
//   PipelineOptions o;
//   o.iso_auto = true;         // Otsu's threshold, as --iso auto
//   o.memory = "512MiB";       // out of core; empty: in core, the mesh returned in r.mesh
//   o.output = "ct.ply";
//   o.stats = true;
//   const PipelineResult r = run_pipeline(in, o);   // r.stats: what --stats writes
//
// In core the mesh is returned (in the frame it is written in) and, with `output`, written. Out of
// core (`memory` set) it is streamed into `output` (binary PLY or STL) and only the counts and the
// statistics come back. MPI runs stay the CLI's (tiler/mpi_extract.h); they build their
// statistics with tiled_stats() below.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>

#include "core/extract/extract.h"
#include "core/mesh/mesh.h"
#include "core/mesh/mesh_quality.h"
#include "core/progress.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/volume_io.h"
#include "tiler/stats_json.h"
#include "tiler/tiled_extract.h"

namespace isotile {

// Where the samples come from.
struct PipelineInput {
  // Anything read_volume() reads: a file, a DICOM or TIFF directory, a numbered TIFF pattern, a
  // procedural field field:NAME:N. With `volume` set, only the input's name (in the stats'
  // "input" and in messages; a field spec still gives the field's default isovalue and distance).
  std::string path;
  RawOptions raw;  // raw dims, type, byte order; spacing and origin overrides; DICOM series
  // Samples already in memory (an array, a volume read earlier), used in place of reading
  // `path`; in core only. The caller keeps them alive during the run.
  const VolumeView* volume = nullptr;
};

struct PipelineOptions {
  // The isovalue: a finite number; unset, a field's own (a volume file has none: InputError);
  // iso_auto: Otsu's threshold of the samples' histogram (core/volume/otsu_isovalue.h), which
  // takes the place of `iso` where both are set.
  std::optional<double> iso;
  bool iso_auto = false;
  // Method, backend, normals, Dual Contouring's and Macet's options. Its iso, cells, progress and
  // warn are set by the run.
  ExtractOptions extract;
  bool world_frame = true;           // positions in the volume's world frame (else the grid frame)
  double simplify = 1;               // fraction of faces kept, (0, 1]; 1: off
  bool check_intersections = false;  // in core: the stats' self_intersections
  // No pair of samples straddles the isovalue: false throws InputError with the samples' range;
  // true gives the empty mesh.
  bool allow_empty = false;
  // Out of core: each brick's working set within this size ("256MiB", "2GB"; parsed by
  // parse_memory_size, tiler/brick_plan.h); empty: in core.
  std::string memory;
  // The mesh file (.ply, .obj, .stl, .off by extension; out of core binary .ply or .stl). Empty:
  // nothing is written (in core only).
  std::string output;
  bool ascii = false;  // ASCII PLY
  // Build PipelineResult::stats (the measures cost time: topology, quality, distances).
  bool stats = false;
  // Measure the radius ratios alone (PipelineResult::quality), as a front end that shows them
  // without the other statistics does (the MeshLab plugin); stats implies it.
  bool quality = false;
  // In core: hand the mesh back in PipelineResult::mesh (else it is dropped after the write).
  bool keep_mesh = true;
  // Report the samples' lowest and highest value (PipelineResult::range), for a front end that
  // shows them (the MeshLab plugin's log). In core one value_range() pass over the samples, or
  // none where iso_auto's histogram has them; out of core only from iso_auto's histogram (another
  // pass over the file would cost as much as the extraction's count): unset without iso_auto.
  bool range = false;
  // Told of the run's progress (handed down to every stage); cancelling throws Cancelled and
  // leaves no output file. Null: nobody listens.
  Progress* progress = nullptr;
  // One line per step ("reading ct.nrrd", "--iso auto: 412 (...)", ...), as the CLI prints them;
  // empty: silent.
  std::function<void(const std::string&)> log;
  // Told what the run does other than asked while its result stays right (core/progress.h: a GPU
  // backend's failure under auto, a memory budget the surface overflows); null: stderr, as
  // "isotile: warning: LINE" (the CLI's, shown under --quiet too).
  Warn warn;
  // In core with `output`: called with the mesh as written (world frame where it applies), e.g.
  // to draw it; its time is left out of the stats' write seconds.
  std::function<void(const Mesh&)> written;
};

struct PipelineResult {
  Mesh mesh;  // in core with keep_mesh: the final mesh, in the frame chosen (as written)
  double iso = 0;
  std::optional<double> auto_iso;  // set when iso_auto chose it
  // The samples' lowest and highest value: set in core with options.range or iso_auto, out of
  // core with iso_auto (the histogram's bounds).
  std::optional<std::pair<double, double>> range;
  // A DICOM series' UID and description, from the headers the run read (empty for other inputs
  // and for input.volume), for a front end that names the series (the MeshLab plugin's layer).
  std::string series_uid, series_description;
  Backend backend = Backend::Cpu;  // where it ran
  std::int64_t bricks = 1;
  std::uint64_t triangles = 0, vertices = 0;  // of the final mesh (quads count as two)
  std::uint64_t triangles_extracted = 0;      // before simplification
  QualityStats quality;  // of the final mesh, when options.stats or options.quality
  StatsJson stats;       // `isotile extract --stats`'s object, when options.stats; else null
};

// Throws InputError for bad options or input (one message naming the problem), IoError,
// CapacityError, Cancelled. The output is written whole or not at all (core/mesh/atomic_file.h):
// an error or a cancel before the write completes leaves no file (and an earlier one as it was);
// only the `written` callback and the measures run after it.
PipelineResult run_pipeline(const PipelineInput& input, const PipelineOptions& options);

// The checks of the options alone that run_pipeline() makes first (simplify and macet_relax in
// range, macet_relax with Macet only, the method available on the backend), for a front end
// that wants their errors before its own later ones. Throws InputError.
void check_pipeline_options(const PipelineOptions& options);

// The extraction options a run of `options` on `input` starts from, after the checks of
// check_pipeline_options(): options.extract with the isovalue set (`iso`; else a procedural
// field's own; with iso_auto left for the samples' histogram to choose) and no cells or progress.
// The MPI path (tiler/mpi_extract.h) starts from the same. Throws InputError.
ExtractOptions pipeline_extract_options(const PipelineInput& input, const PipelineOptions& options);

// --iso auto's choice from `histogram`: the isovalue, said through `log` with the samples'
// range; returns the stats' "iso_auto" object.
StatsJson choose_isovalue(const ValueHistogram& histogram, double& iso,
                          const std::function<void(const std::string&)>& log);

// The tiler's options of an out-of-core run of `options` (memory, format, simplify, progress,
// quality measures when the stats are wanted); throws InputError for what a streamed run cannot
// do (ASCII, --check-intersections); warns of a budget above what the process can have.
TiledOptions tiled_options(const PipelineOptions& options, const ExtractOptions& extract,
                           MeshFormat format);

// "extracted N triangles[, simplified to M], V vertices in B bricks of XxYxZ cells": an
// out-of-core run's summary line.
std::string tiled_summary(const TiledResult& result, bool simplified);

// The statistics of an out-of-core run (single process or MPI).
struct TiledStatsInput {
  std::string input, output;
  Index3 dims{0, 0, 0};
  ScalarType type = ScalarType::Float32;
  const ExtractOptions* extract = nullptr;  // method, iso, ... as run
  StatsJson auto_iso;                       // null unless iso_auto
  const TiledResult* result = nullptr;
  bool world_frame = false;  // the mesh was written in the world frame
  std::uint64_t memory = 0;
  bool region_reads = true;
  double simplify = 1;
  double seconds_total = 0;
};
StatsJson tiled_stats(const TiledStatsInput& in);

}  // namespace isotile
