// isotile: the batch command-line front end of the isotile library.
//
//   isotile extract INPUT -o OUT.{ply,obj,stl,off} [--iso V] [--method mc] [--backend ...]
//   isotile info INPUT [--json]
//   isotile quality MESH [--json]
//   isotile simplify IN OUT --ratio R | --faces N | --max-error E
//   isotile demo [-o OUT]
//
// Errors are one line on stderr and a non-zero exit status (1 for failures, 2 for bad usage).
// Progress and timings go to stderr unless --quiet; machine-readable output goes to stdout or to
// the --stats file.
#include <malloc.h>
#include <sys/resource.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/field_distance.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/mesh/self_intersections.h"
#include "core/mesh/surface_distance.h"
#include "core/simplify/simplify.h"
#include "core/volume/image_headers.h"
#include "core/volume/itk_reader.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#ifdef ISOTILE_HAVE_GL
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#endif
#include "tiler/gpu_report_json.h"
#include "tiler/input_options.h"
#include "tiler/mpi_launch.h"
#include "tiler/render_command.h"
#include "tiler/source_histogram.h"
#include "tiler/tiled_extract.h"
#ifdef ISOTILE_HAVE_MPI
#include "tiler/mpi_extract.h"
#endif

namespace {

using namespace isotile;
using json = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

bool g_quiet = false;

#ifdef ISOTILE_HAVE_MPI
// Set when started by an MPI launcher (tiler/mpi_launch.h); only rank 0 reports.
std::optional<MpiSession> g_mpi;
// Inside extract_distributed: an error that is not an AgreedError is this rank's alone, and the
// other ranks wait for it in a collective, so the job is aborted.
bool g_distributed = false;
#endif

void progress(const std::string& message) {
  if (!g_quiet) std::fprintf(stderr, "isotile: %s\n", message.c_str());
}

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

std::string fmt_seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f s", s);
  return buf;
}

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

// Options describing how to read a raw input, shared by `extract` and `info`.
struct InputArgs {
  std::string input;
  std::string dims, type, spacing, origin, endian = "little", series;

  void add_to(CLI::App& app) {
    app.add_option("INPUT", input,
                   "Volume file by extension: NRRD (.nrrd, .nhdr), OpenVDB (.vdb), NIfTI (.nii, "
                   ".nii.gz), MetaImage (.mha, .mhd), TIFF (.tif, .tiff), MRC/CCP4 (.mrc, .mrcs, "
                   ".map, .ccp4), DICOM (.dcm, .ima, or any file with DICOM's DICM marker), raw "
                   "(any other name: NAME_XxYxZ_TYPE.raw[.gz], or --dims and --type; .gz is "
                   "gunzipped); a DICOM or TIFF directory, a numbered TIFF pattern "
                   "(slice_%03d.tif) or a procedural field field:NAME:N (sphere, torus, gyroid, "
                   "csg-box, marschner-lobb)")
        ->required();
    app.add_option("--dims", dims,
                   "Raw input: samples along x,y,z, e.g. 256,256,128 (default: from the file "
                   "name NAME_XxYxZ_TYPE.raw)");
    app.add_option("--type", type,
                   "Raw input: int8|uint8|int16|uint16|int32|uint32|float32|float64 (default: "
                   "from the file name)");
    app.add_option("--spacing", spacing,
                   "Sample spacing x,y,z, finite and above 0 (overrides the file's; default: the "
                   "file's, 1,1,1 for raw input)");
    app.add_option("--origin", origin,
                   "World position x,y,z of the first sample, finite (overrides the file's; "
                   "default: the file's, 0,0,0 for raw input)");
    app.add_option("--endian", endian, "Raw input byte order")
        ->check(CLI::IsMember({"little", "big"}));
    app.add_option("--series", series,
                   "DICOM: the SeriesInstanceUID to read where the directory holds several "
                   "(default: the only one)");
  }

  RawOptions raw_options() const {
    RawOptions o = parse_input_text(
        {.dims = dims, .type = type, .spacing = spacing, .origin = origin, .endian = endian});
    o.series = series;
    return o;
  }
};

// A measure without a value (the radius ratios of no triangle) is null, never a made-up 0.
json quality_json(const QualityStats& q) {
  json j;
  const auto measured = [&](double v) { return q.triangles > 0 ? json(v) : json(nullptr); };
  j["radius_ratio_min"] = measured(q.min);
  j["radius_ratio_mean"] = measured(q.mean);
  j["radius_ratio_q001"] = measured(q.q001);
  j["radius_ratio_q01"] = measured(q.q01);
  j["radius_ratio_median"] = measured(q.median);
  j["radius_ratio_histogram"] = q.histogram;
  j["degenerate_triangles"] = q.degenerate;
  return j;
}

// `border_known`: the mesh's volume box is known (an extraction); a mesh read from a file has
// none, so whether its boundary lies on a volume border cannot be told: watertight is null.
// A mesh without faces is neither closed nor open: both are null.
json topology_json(const TopologyStats& t, bool border_known) {
  json j;
  j["boundary_edges"] = t.boundary_edges;
  j["border_boundary_edges"] = t.border_boundary_edges;
  j["nonmanifold_edges"] = t.nonmanifold_edges;
  j["nonmanifold_vertices"] = t.nonmanifold_vertices;
  j["inconsistently_oriented_edges"] = t.inconsistently_oriented_edges;
  j["euler"] = t.euler;
  j["components"] = t.components;
  j["closed"] = t.faces > 0 ? json(t.closed) : json(nullptr);
  j["watertight"] = border_known && t.faces > 0 ? json(t.watertight) : json(nullptr);
  return j;
}

// Standard output's buffered writes that failed (a full disk, a closed pipe's EPIPE, /dev/full):
// an IoError, so that the run exits 1 instead of 0 with the output lost.
void flush_stdout() {
  // std::cout writes through stdout's buffer (synced with stdio), so its flush is stdout's: the
  // first failing flush sets errno, the second only confirms.
  errno = 0;
  std::cout.flush();
  const bool flushed = std::fflush(stdout) == 0;
  const int err = errno;
  if (flushed && !std::ferror(stdout) && std::cout.good()) return;
  throw IoError(std::string("cannot write standard output") +
                (err != 0 ? std::string(": ") + std::strerror(err) : std::string()));
}

void write_text(const std::string& path, const std::string& text) {
  if (path == "-") {
    std::fwrite(text.data(), 1, text.size(), stdout);
    flush_stdout();
    return;
  }
  AtomicFile f(path);
  f.write(text.data(), text.size());
  f.commit();
}

// --- extract -------------------------------------------------------------------------------

struct ExtractArgs {
  InputArgs in;
  std::string output;
  std::string iso;  // a number, "auto" or empty (a field's own)
  bool allow_empty = false;
  std::string method = "mc";
  std::string backend = "auto";
  std::string stats;
  bool normals = false;
  bool ascii = false;
  std::string dc_solver = "mass";
  std::string dc_hermite = "central";
  std::string dc_vertices = "patch";
  std::string quality = "fast";  // Macet
  double macet_relax = 0.0;
  bool quads = false;
  bool check_intersections = false;
  std::string memory;  // empty: in core
  std::string frame = "world";
  double simplify = 1;  // fraction of faces kept; 1: off
  std::string render;   // --render PICTURE.png: drawn from the written mesh
};

Method parse_method(const std::string& s) {
  if (s == "mc") return Method::MarchingCubes;
  if (s == "macet") return Method::Macet;
  return Method::DualContouring;
}

Backend parse_backend(const std::string& s) {
  if (s == "cpu") return Backend::Cpu;
  if (s == "gs") return Backend::GeometryShader;
  if (s == "hp") return Backend::HistoPyramid;
  return Backend::Auto;
}

// --- simplification shared by `extract --simplify` and `simplify` -----------------------------

SimplifyOptions simplify_options(double ratio, std::uint64_t faces, double max_error,
                                 double min_quality, bool relax) {
  SimplifyOptions o;
  o.ratio = ratio;
  o.faces = faces;
  o.max_error = max_error;
  o.min_quality = min_quality;
  o.relax = relax;
  o.progress = [](std::string_view pass, std::int64_t done, std::int64_t total) {
    const std::int64_t step = std::max<std::int64_t>(1, total / 10);
    if (done != total && done % step != 0) return;
    progress("simplify " + std::string(pass) + ": " + std::to_string(done) + "/" +
             std::to_string(total) + " regions");
  };
  return o;
}

// Stats keys of a simplification; `scale` turns mesh units into voxels where known.
json simplify_json(const SimplifyStats& s, const Mesh& before, const Mesh& after,
                   const Vec3d& scale) {
  json j;
  j["triangles_before"] = s.faces_before;
  j["simplify_target_faces"] = s.target_faces;
  j["simplify_regions"] = s.regions;
  j["simplify_seam_regions"] = s.seam_regions;
  j["simplify_collapses"] = s.collapses;
  j["simplify_flips"] = s.flips;
  j["simplify_relaxed"] = s.relaxed;
  j["simplify_boundary_vertices"] = s.boundary_vertices;
  j["simplify_split_vertices"] = s.split_vertices;
  j["simplify_split_copies"] = s.split_copies;
  j["simplify_unlinked_faces"] = s.unlinked_faces;
  const SurfaceDistance d = surface_distance(before, after, {.scale = scale});
  j["simplify_hausdorff_mean"] = d.mean();
  j["simplify_hausdorff_max"] = d.max();
  const OneWayDistance& worst = d.a_to_b.max >= d.b_to_a.max ? d.a_to_b : d.b_to_a;
  j["simplify_hausdorff_max_at"] = {worst.max_at[0] / scale[0], worst.max_at[1] / scale[1],
                                    worst.max_at[2] / scale[2]};
  j["simplify_hausdorff_max_direction"] =
      d.a_to_b.max >= d.b_to_a.max ? "input to result" : "result to input";
  return j;
}

#ifdef ISOTILE_HAVE_MPI
// A distributed run's keys besides the single-process ones (docs/cli.md): every rank's times
// and bricks, the load imbalance, and each brick's measured seconds per pass.
json distributed_json(const DistributedResult& d) {
  json j;
  j["ranks"] = d.ranks;
  json per_rank = json::array();
  double rss = 0;
  for (const RankTimes& t : d.rank_times) {
    per_rank.push_back({{"seconds_count", t.seconds_count},
                        {"seconds_extract", t.seconds_extract},
                        {"bricks_counted", t.bricks_counted},
                        {"bricks_extracted", t.bricks_extracted},
                        {"triangles", t.triangles},
                        {"planned_cost", t.planned_cost},
                        {"peak_rss_mb", t.peak_rss_mb}});
    rss = std::max(rss, t.peak_rss_mb);
  }
  j["per_rank"] = per_rank;
  j["load_imbalance"] = d.load_imbalance;
  j["load_imbalance_planned"] = d.planned_imbalance;
  j["brick_seconds"] = {{"count", d.brick_seconds_count}, {"extract", d.brick_seconds_extract}};
  j["brick_faces"] = d.brick_faces;
  j["peak_rss_mb"] = rss;  // the largest rank's
  return j;
}
#endif

// glibc maps every large block afresh and unmaps it when freed, so each array an extraction
// allocates after freeing another is faulted in and zero-filled by the kernel again. Out of core,
// bricks allocate and free arrays of the same sizes, brick after brick: 2.0M page faults and 4.5 s
// of system time on a 4 GiB volume (docs/tiler.md). In core, the extractors' passes free scratch
// tables before the next allocates (Macet's smoothing tables, then the mesh: 11% of a one-shot
// Macet run on bonsai). Kept on the heap, later arrays reuse the freed pages; peak RSS is the
// same, since the freed arrays were resident at once anyway. One arena: a worker thread's arena
// maps large blocks whatever M_MMAP_MAX says.
void keep_freed_memory_for_reuse() {
#ifdef __GLIBC__
  mallopt(M_ARENA_MAX, 1);
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max());
#endif
}

// Gives the heap's free blocks back to the kernel (they are otherwise kept: see
// keep_freed_memory_for_reuse).
void return_freed_memory() {
#ifdef __GLIBC__
  malloc_trim(0);
#endif
}

// Frees the volume's samples and gives every freed block back to the kernel. The heap keeps
// freed blocks (keep_freed_memory_for_reuse), so without the trim the output file's pages (tmpfs
// or page cache) could not take the volume's place and would be fresh pages. On the development
// machines (virtual, their host slow to supply fresh pages once they hold several GB) a 4 GiB
// volume's 3.4 GB mesh was then written at 0.35 GB/s, against 1.9 GB/s with the samples' pages
// given back just before (docs/benchmarks.md, "In-core stages at scale").
void release_volume(Volume& volume) {
  volume = Volume();
  return_freed_memory();
}

// TBB creates its worker threads on the first parallel loop, which in a one-shot run is the
// extraction's first pass. Started there, they made cold extractions slower and more scattered
// (engine: DC 35.7 against 27.2 ms, MC 15.0 against 13.3 ms, medians of 13 fresh processes;
// docs/benchmarks.md, "Worker threads started before the read");
// an empty task enqueued before the volume is read starts them while the main thread reads, and
// nothing waits for it. With one thread allowed, an enqueued task would still get a worker of its
// own, so none is asked for.
void start_worker_threads() {
  if (tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism) > 1)
    tbb::this_task_arena::enqueue([] {});
}

// --iso auto: Otsu's threshold of the samples' histogram (core/volume/otsu_isovalue.h), said on
// stderr with the samples' range; returns the stats' "iso_auto" object.
json choose_isovalue(const ValueHistogram& histogram, double& iso) {
  iso = otsu_isovalue(histogram);
  std::ostringstream s;
  s.precision(10);
  s << "--iso auto: " << iso << " (Otsu's threshold; the samples range from " << histogram.min
    << " to " << histogram.max << ")";
  progress(s.str());
  return {{"rule", "otsu"}, {"min", histogram.min}, {"max", histogram.max}};
}

// Out of core: brick by brick within --memory, streamed into the output file.
int run_extract_tiled(const ExtractArgs& args, const ExtractOptions& options, MeshFormat format,
                      Clock::time_point t_total) {
  TiledOptions to;
  to.extract = options;
  to.memory = parse_memory_size(args.memory);
  to.allow_empty = args.allow_empty;
  to.format = format;
  to.simplify = args.simplify;
  // The radius-ratio statistics cost a fifth of a streamed run; only --stats reports them.
  to.quality = !args.stats.empty();
  if (args.ascii) throw InputError("--memory writes binary PLY or STL; drop --ascii");
  if (args.check_intersections)
    throw InputError(
        "--check-intersections needs the whole mesh in memory; drop --memory, or run "
        "`isotile quality --check-intersections` on the output");
  to.progress = [&](std::string_view pass, std::int64_t done, std::int64_t total) {
    // About twenty lines per pass, whatever the brick count.
    const std::int64_t step = std::max<std::int64_t>(1, total / 20);
    if (done != total && done % step != 0) return;
    progress(std::string(pass) + ": " + std::to_string(done) + "/" + std::to_string(total) +
             " bricks");
  };
  TiledResult r;
  Index3 dims{0, 0, 0};
  ScalarType type = ScalarType::Float32;
  json distributed;
  const bool world = args.frame == "world";
  bool region_reads = true;
  json auto_iso;
#ifdef ISOTILE_HAVE_MPI
  if (g_mpi) {
    // Every rank reads the whole input once for the histogram and finds the same value.
    if (args.iso == "auto")
      auto_iso = choose_isovalue(
          source_histogram(*open_volume_source(args.in.input, args.in.raw_options(), to.memory),
                           to.memory),
          to.extract.iso);
    progress("extracting " + args.in.input + " brick by brick within " + args.memory + " on " +
             std::to_string(g_mpi->size) + " MPI ranks");
    g_distributed = true;
    const DistributedResult d =
        extract_distributed(args.in.input, args.in.raw_options(), to, world, args.output);
    g_distributed = false;
    if (g_mpi->rank != 0) return 0;
    r = d.tiled;
    dims = d.dims;
    type = d.type;
    region_reads = !d.source_in_memory;
    to.frame.active = d.world_frame;  // for the stats' "frame" only: the ranks wrote the mesh
    distributed = distributed_json(d);
  } else
#endif
  {
    auto source = open_volume_source(args.in.input, args.in.raw_options(), to.memory);
    check_grid_geometry(source->spacing, source->origin, source->world, args.in.input);
    if (world) to.frame = mesh_frame(source->origin, source->world);
    dims = source->dims;
    type = source->type;
    region_reads = !source->in_memory();
    if (args.iso == "auto") {
      progress("reading " + args.in.input + " once for --iso auto's histogram");
      auto_iso = choose_isovalue(source_histogram(*source, to.memory), to.extract.iso);
    }
    progress(
        "extracting " + args.in.input + " (" + std::to_string(dims[0]) + "x" +
        std::to_string(dims[1]) + "x" + std::to_string(dims[2]) + " " +
        std::string(scalar_name(type)) + ") brick by brick within " + args.memory +
        (source->in_memory() ? " (this input cannot be read by region: read whole first)" : ""));
    r = extract_tiled(*source, to, args.output);
  }
  progress(
      (to.simplify < 1
           ? "extracted " + std::to_string(r.triangles_extracted) + " triangles, simplified to "
           : std::string("extracted ")) +
      std::to_string(r.triangles) + " triangles, " + std::to_string(r.vertices) + " vertices in " +
      std::to_string(r.plan.total()) + " bricks of " + std::to_string(r.plan.brick[0]) + "x" +
      std::to_string(r.plan.brick[1]) + "x" + std::to_string(r.plan.brick[2]) + " cells");
  if (!args.stats.empty()) {
    json j;
    j["input"] = args.in.input;
    j["output"] = args.output;
    j["dims"] = dims;
    j["type"] = scalar_name(type);
    j["iso"] = to.extract.iso;
    if (!auto_iso.is_null()) j["iso_auto"] = auto_iso;
    j["method"] = method_name(options.method);
    if (options.method == Method::Macet) {
      j["quality"] = args.quality;
      j["macet_relax"] = options.macet_relax;
    }
    if (options.method == Method::DualContouring) j["dc_vertices"] = args.dc_vertices;
    j["backend"] = backend_name(r.backend);
    j["backend_reason"] = choose_backend(options).reason;
    j["threads"] = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
    j["frame"] = to.frame.active ? "world" : "grid";
    j["triangles"] = r.triangles;
    j["vertices"] = r.vertices;
    j.update(quality_json(r.quality));
    // Topology needs every edge's faces at once; a streamed run does not hold them.
    for (const char* key : {"boundary_edges", "nonmanifold_edges", "euler", "closed", "watertight"})
      j[key] = nullptr;
    j["bricks"] = r.plan.total();
    j["brick_cells"] = r.plan.brick;
    j["brick_grid"] = r.plan.count;
    j["bricks_extracted"] = r.bricks_extracted;
    j["memory_budget"] = to.memory;
    j["region_reads"] = region_reads;
    j["largest_brick_bytes"] = r.largest_brick_bytes;
    j["seconds"] = {{"count", r.seconds_count},
                    {"extract", r.seconds_extract},
                    {"total", seconds_since(t_total)}};
    const TiledResult::Stages& st = r.stages;
    j["seconds"]["stages"] = {{"read", st.read},   {"count", st.count},     {"extract", st.extract},
                              {"index", st.index}, {"records", st.records}, {"write", st.write}};
    if (to.simplify < 1) {
      j["simplify"] = to.simplify;
      j["triangles_before"] = r.triangles_extracted;
      j["simplify_target_faces"] = r.simplify.target_faces;
      // Bricks are simplified with their seams locked, then the seams in cells of a grid
      // shifted by half a brick: the result depends on this plan (docs/simplify.md).
      j["simplify_brick_plan"] = {
          {"brick_cells", r.plan.brick}, {"brick_grid", r.plan.count}, {"seam_grid", r.seam_cells}};
      j["simplify_collapses"] = r.simplify.collapses;
      j["simplify_split_vertices"] = r.simplify.split_vertices;
      j["simplify_unlinked_faces"] = r.simplify.unlinked_faces;
      // The distance needs the extracted and the simplified mesh whole.
      j["simplify_hausdorff_mean"] = nullptr;
      j["simplify_hausdorff_max"] = nullptr;
      j["seconds"]["seams"] = r.seconds_seams;
    }
    j["peak_rss_mb"] = peak_rss_mb();
    if (!distributed.is_null()) j.update(distributed);
    write_text(args.stats, j.dump(2) + "\n");
  }
  if (!args.render.empty()) render_extracted_file(args.output, args.render, g_quiet);
  progress("done in " + fmt_seconds(seconds_since(t_total)));
  return 0;
}

int run_extract(const ExtractArgs& args) {
  const auto t_total = Clock::now();
  keep_freed_memory_for_reuse();
  start_worker_threads();
  // Fail on a bad output name or an unavailable method before spending time on reading: the
  // outputs' folders, their kinds (a device or FIFO cannot take the streamed writer's
  // positioned writes) and the extension.
  check_output(args.output, !args.memory.empty() && args.simplify >= 1);
  const MeshFormat format = mesh_format_from_path(args.output);
  if (!args.stats.empty() && args.stats != "-") check_output(args.stats);
  args.in.raw_options();  // --dims, --spacing, ... checked before anything is read
  if (!args.render.empty()) check_picture_path(args.render);
  ExtractOptions options;
  options.method = parse_method(args.method);
  options.backend = parse_backend(args.backend);
  options.normals = args.normals;
  options.dc_solver = args.dc_solver == "particle" ? DcSolver::Particle
                      : args.dc_solver == "qef"    ? DcSolver::Qef
                                                   : DcSolver::MassPoint;
  options.keep_quads = args.quads;
  options.dc_hermite = args.dc_hermite == "eno" ? DcHermite::Eno : DcHermite::Central;
  options.dc_vertices = args.dc_vertices == "cell" ? DcVertices::Cell : DcVertices::Patch;
  options.quality = args.quality == "max" ? MacetQuality::Max : MacetQuality::Fast;
  options.macet_relax = args.macet_relax;
  if (options.macet_relax > 0 && options.method != Method::Macet)
    throw InputError("--macet-relax applies to --method macet only");
  BackendChoice choice = choose_backend(options);
  const Backend backend = choice.backend;

  const std::optional<FieldSpec> field = parse_field_spec(args.in.input);
  const bool iso_auto = args.iso == "auto";
  if (!args.iso.empty() && !iso_auto) {
    char* end = nullptr;
    options.iso = std::strtod(args.iso.c_str(), &end);
    if (end == args.iso.c_str() || *end != '\0' || !std::isfinite(options.iso))
      throw InputError("--iso must be a finite number or 'auto', got '" + args.iso + "'");
  } else if (field && !iso_auto) {
    options.iso = field_default_iso(field->kind);
  } else if (!iso_auto) {
    throw InputError(
        "--iso is required for a volume file: a number, or 'auto' for Otsu's "
        "threshold of the samples (`isotile info " +
        args.in.input + "` shows their range and histogram)");
  }
  const bool simplifying = args.simplify < 1;
  if (simplifying && options.keep_quads)
    throw InputError("--simplify gives triangles; drop --quads");
  if (!args.memory.empty()) return run_extract_tiled(args, options, format, t_total);

  progress("reading " + args.in.input);
  auto t0 = Clock::now();
  Volume volume = read_volume(args.in.input, args.in.raw_options());
  const double t_read = seconds_since(t0);
  // Only extract() and the repairs below read the samples; the rest of this run uses the view's
  // dims and frame, so its data pointer is cleared when the samples are released.
  VolumeView view = volume.view();
  check_grid_geometry(view.spacing, view.origin, view.world, args.in.input);
  progress("read " + std::to_string(view.dims[0]) + "x" + std::to_string(view.dims[1]) + "x" +
           std::to_string(view.dims[2]) + " " + std::string(scalar_name(view.type)) + " in " +
           fmt_seconds(t_read));

  json auto_iso;
  if (iso_auto) auto_iso = choose_isovalue(value_histogram(view), options.iso);
  progress("extracting (" + std::string(method_name(options.method)) + ", " +
           std::string(backend_name(backend)) + ", iso " + std::to_string(options.iso) + ")");
  t0 = Clock::now();
  Mesh mesh = extract(view, options, &choice);
  const double t_extract = seconds_since(t0);
  // No face: found from the mesh, at no cost to a run that has one. The range is a cheap pass.
  if (mesh.triangles.empty() && mesh.quads.empty() && !args.allow_empty) {
    const auto [lo, hi] = value_range(view);
    if (!(lo < options.iso && options.iso <= hi)) throw_no_surface(options.iso, std::pair(lo, hi));
  }
  progress("extracted " + std::to_string(mesh.triangles.size()) + " triangles, " +
           std::to_string(mesh.positions.size()) + " vertices in " + fmt_seconds(t_extract));

  // Dual Contouring's patch repairs (reported by --stats) are the last reader of the samples.
  std::optional<DcPatchRepairs> repairs;
  double t_repairs = 0;
  if (!args.stats.empty() && options.method == Method::DualContouring &&
      options.dc_vertices == DcVertices::Patch) {
    t0 = Clock::now();
    repairs = dual_contouring_patch_repairs(view, options.iso);
    t_repairs = seconds_since(t0);
  }
  // Nothing below reads the samples (see release_volume), and simplification and the write both
  // gain from their memory; the time is counted in the stage that comes next.
  t0 = Clock::now();
  release_volume(volume);
  view.data = nullptr;
  const double t_release = seconds_since(t0);

  // The extracted mesh is kept past simplification only for the stats' distance measure.
  std::optional<Mesh> extracted;
  SimplifyStats sstats;
  double t_simplify = 0;
  if (simplifying) {
    progress("simplifying to " + std::to_string(args.simplify) + " of the faces");
    t0 = Clock::now();
    Mesh simplified = simplify(mesh, simplify_options(args.simplify, 0, 0, 0.3, true), &sstats);
    t_simplify = seconds_since(t0) + t_release;
    progress("simplified to " + std::to_string(simplified.triangles.size()) + " triangles in " +
             fmt_seconds(t_simplify));
    if (!args.stats.empty()) extracted = std::move(mesh);
    mesh = std::move(simplified);
  }

  progress("writing " + args.output);
  t0 = Clock::now();
  // The simplifier's freed memory would otherwise stay resident through the measures: peak RSS
  // 13.8 GB against 9.5 GB for 22M triangles simplified to a tenth with --stats.
  if (simplifying) return_freed_memory();
  // Positions go out in the volume's world frame; the measures below stay in the grid frame
  // (the volume border is a box there), as a streamed run's do.
  const MeshFrame frame = args.frame == "world" ? mesh_frame(view) : MeshFrame{};
  double t_render = 0;  // --render draws the mesh as written
  if (frame.active) {
    Mesh world = mesh;
    apply_frame(frame, world);
    write_mesh(world, args.output, {.format = format, .ascii = args.ascii, .write_normals = true});
    if (!args.render.empty()) t_render = render_extracted(world, args.render, g_quiet);
  } else {
    write_mesh(mesh, args.output, {.format = format, .ascii = args.ascii, .write_normals = true});
    if (!args.render.empty()) t_render = render_extracted(mesh, args.render, g_quiet);
  }
  const double t_write = seconds_since(t0) - t_render + (simplifying ? 0.0 : t_release);

  if (args.stats.empty()) {
    progress("done in " + fmt_seconds(seconds_since(t_total)));
    return 0;
  }
  t0 = Clock::now();
  const QualityStats q = triangle_quality(mesh);
  const TopologyStats topo = mesh_topology(mesh, volume_border(view, options.method));
  json j;
  j["input"] = args.in.input;
  j["output"] = args.output;
  j["dims"] = view.dims;
  j["type"] = scalar_name(view.type);
  j["iso"] = options.iso;
  if (!auto_iso.is_null()) j["iso_auto"] = auto_iso;
  j["method"] = method_name(options.method);
  if (options.method == Method::Macet) {
    j["quality"] = args.quality;
    j["macet_relax"] = options.macet_relax;
  }
  j["backend"] = backend_name(choice.backend);
  j["backend_reason"] = choice.reason;
  j["threads"] = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
  j["frame"] = frame.active ? "world" : "grid";
  j["triangles"] = mesh.triangles.size() + 2 * mesh.quads.size();
  j["vertices"] = mesh.positions.size();
  j.update(quality_json(q));
  j.update(topology_json(topo, true));
  j["bricks"] = 1;
  if (options.method == Method::DualContouring) {
    j["dc_vertices"] = args.dc_vertices;
    if (repairs) {
      j["dc_flipped_faces"] = repairs->flipped_faces;
      j["dc_border_cut_cells"] = repairs->border_cut_cells;
    }
  }
  if (args.check_intersections) j["self_intersections"] = self_intersections(mesh).pairs;
  if (extracted) {
    j["simplify"] = args.simplify;
    j.update(simplify_json(sstats, *extracted, mesh,
                           {1 / view.spacing[0], 1 / view.spacing[1], 1 / view.spacing[2]}));
  }
  if (field) {
    const FieldDistance d = field_distance(*field, mesh, view.origin, view.spacing);
    const bool none = mesh.positions.empty();  // no vertex: no distance
    j["distance_mean"] = none ? json(nullptr) : json(d.mean);
    j["distance_max"] = none ? json(nullptr) : json(d.max);
  }
  const double t_measure = seconds_since(t0) + t_repairs;
  j["seconds"] = {{"read", t_read},
                  {"extract", t_extract},
                  {"write", t_write},
                  {"measure", t_measure},
                  {"total", seconds_since(t_total)}};
  if (simplifying) j["seconds"]["simplify"] = t_simplify;
  add_gpu_report(j, choice.gpu);  // seconds.gl, upload_gbps, gl_program_cache (docs/cli.md)
  j["peak_rss_mb"] = peak_rss_mb();
  write_text(args.stats, j.dump(2) + "\n");
  progress("done in " + fmt_seconds(seconds_since(t_total)));
  return 0;
}

// --- simplify ------------------------------------------------------------------------------

struct SimplifyArgs {
  std::string input, output, stats;
  double ratio = 0, max_error = 0, min_quality = 0.3;
  std::uint64_t faces = 0;
  bool no_relax = false, ascii = false;
};

int run_simplify(const SimplifyArgs& args) {
  const auto t_total = Clock::now();
  check_output(args.output);
  const MeshFormat format = mesh_format_from_path(args.output);
  if (!args.stats.empty() && args.stats != "-") check_output(args.stats);
  if ((args.ratio > 0) + (args.faces > 0) + (args.max_error > 0) != 1)
    throw InputError("give exactly one of --ratio, --faces and --max-error");
  progress("reading " + args.input);
  auto t0 = Clock::now();
  Mesh mesh = read_mesh(args.input);
  const double t_read = seconds_since(t0);
  progress("read " + std::to_string(mesh.triangles.size() + 2 * mesh.quads.size()) +
           " triangles, " + std::to_string(mesh.positions.size()) + " vertices in " +
           fmt_seconds(t_read));
  t0 = Clock::now();
  SimplifyStats sstats;
  Mesh out = simplify(
      mesh,
      simplify_options(args.ratio, args.faces, args.max_error, args.min_quality, !args.no_relax),
      &sstats);
  const double t_simplify = seconds_since(t0);
  progress("simplified to " + std::to_string(out.triangles.size()) + " triangles in " +
           fmt_seconds(t_simplify));
  progress("writing " + args.output);
  t0 = Clock::now();
  write_mesh(out, args.output, {.format = format, .ascii = args.ascii, .write_normals = true});
  const double t_write = seconds_since(t0);
  const double t_done = seconds_since(t_total);
  if (!args.stats.empty()) {
    t0 = Clock::now();
    json j;
    j["input"] = args.input;
    j["output"] = args.output;
    j["threads"] = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
    j["triangles"] = out.triangles.size();
    j["vertices"] = out.positions.size();
    j.update(quality_json(triangle_quality(out)));
    j.update(topology_json(mesh_topology(out), false));
    j.update(simplify_json(sstats, mesh, out, {1, 1, 1}));
    j["seconds"] = {{"read", t_read},
                    {"simplify", t_simplify},
                    {"write", t_write},
                    {"total", t_done},
                    {"measure", seconds_since(t0)}};
    j["peak_rss_mb"] = peak_rss_mb();
    write_text(args.stats, j.dump(2) + "\n");
  }
  progress("done in " + fmt_seconds(t_done));
  return 0;
}

// --- info ----------------------------------------------------------------------------------

// Where each index axis points in LPS world space: the letter of its largest component
// (L/R along x, P/A along y, S/I along z), e.g. "LPS" for an axis-aligned NIfTI/DICOM axial scan.
std::string axis_letters(const Mat3& d) {
  std::string out;
  for (int a = 0; a < 3; ++a) {
    int best = 0;
    for (int r = 1; r < 3; ++r)
      if (std::abs(d[3 * r + a]) > std::abs(d[3 * best + a])) best = r;
    const bool plus = d[3 * best + a] > 0;
    out += "LPS"[best] == 'L'   ? (plus ? 'L' : 'R')
           : "LPS"[best] == 'P' ? (plus ? 'P' : 'A')
                                : (plus ? 'S' : 'I');
  }
  return out;
}

int run_info(const InputArgs& in, bool as_json) {
  const RawOptions raw = in.raw_options();
  const InputKind kind = input_kind(in.input);
  // A directory of several DICOM series: list them, for --series.
  if (kind == InputKind::Dicom && raw.series.empty() && std::filesystem::is_directory(in.input)) {
    check_dicom_input(in.input);  // before GDCM scans the files (image_headers.h)
    const std::vector<DicomSeriesInfo> series = list_dicom_series(in.input);
    if (series.size() > 1) {
      json list = json::array();
      for (const DicomSeriesInfo& s : series)
        list.push_back({{"uid", s.uid},
                        {"description", s.description},
                        {"dims", {s.columns, s.rows, s.files}}});
      if (as_json) {
        std::cout << json{{"input", in.input}, {"series", list}}.dump(2) << "\n";
        return 0;
      }
      std::printf("input    %s: %zu DICOM series (choose one with --series UID)\n",
                  in.input.c_str(), series.size());
      for (const DicomSeriesInfo& s : series)
        std::printf("  %s  %lld x %lld x %lld  %s\n", s.uid.c_str(),
                    static_cast<long long>(s.columns), static_cast<long long>(s.rows),
                    static_cast<long long>(s.files), s.description.c_str());
      return 0;
    }
  }
  const bool has_header =
      kind != InputKind::Raw && kind != InputKind::Field && kind != InputKind::Vdb;
  const VolumeHeader header = has_header ? read_volume_header(in.input, raw) : VolumeHeader{};
  const Volume volume = read_volume(in.input, raw);
  const VolumeView v = volume.view();
  const auto [lo, hi] = value_range(v);
  constexpr int kBins = 16;
  std::array<std::uint64_t, kBins> hist{};
  // A cheap whole-volume histogram: one pass, per-slab counts merged in slab order.
  std::vector<std::array<std::uint64_t, kBins>> slabs(v.dims[2]);
  const double width = hi > lo ? (hi - lo) / kBins : 1.0;
  tbb::parallel_for(std::int64_t{0}, v.dims[2], [&](std::int64_t k) {
    auto& h = slabs[k];
    h.fill(0);
    for (std::int64_t j = 0; j < v.dims[1]; ++j)
      for (std::int64_t i = 0; i < v.dims[0]; ++i) {
        const int b = static_cast<int>((v.value(i, j, k) - lo) / width);
        ++h[std::clamp(b, 0, kBins - 1)];
      }
  });
  for (const auto& h : slabs)
    for (int b = 0; b < kBins; ++b) hist[b] += h[b];
  const WorldFrame world = v.world ? *v.world : WorldFrame{v.origin, kIdentity3};

  json j;
  j["input"] = in.input;
  j["dims"] = v.dims;
  j["type"] = scalar_name(v.type);
  j["format"] = has_header ? header.format : std::string(input_kind_name(kind));
  j["spacing"] = v.spacing;
  j["origin"] = v.origin;
  // The world frame the mesh is written in (extract --frame world).
  j["world_origin"] = world.origin;
  j["direction"] = {{world.direction[0], world.direction[1], world.direction[2]},
                    {world.direction[3], world.direction[4], world.direction[5]},
                    {world.direction[6], world.direction[7], world.direction[8]}};
  j["orientation"] = axis_letters(world.direction);
  j["rescaled"] = header.rescaled;
  if (header.rescaled)
    j["rescale"] = {{"slope", header.rescale_slope}, {"intercept", header.rescale_intercept}};
  if (!header.series_uid.empty()) {
    j["series_uid"] = header.series_uid;
    j["series_description"] = header.series_description;
  }
  j["bytes"] = volume.byte_size();
  j["min"] = lo;
  j["max"] = hi;
  json bins = json::array();
  for (int b = 0; b < kBins; ++b)
    bins.push_back({{"from", lo + b * width}, {"to", lo + (b + 1) * width}, {"count", hist[b]}});
  j["histogram"] = bins;
  // What `extract --iso auto` would choose (null for a volume of one value: no threshold).
  std::optional<double> auto_iso;
  try {
    auto_iso = otsu_isovalue(value_histogram(v));
  } catch (const InputError&) {
  }
  j["iso_auto"] = auto_iso ? json(*auto_iso) : json(nullptr);
  if (const auto field = parse_field_spec(in.input))
    j["default_iso"] = field_default_iso(field->kind);
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("input    %s\n", in.input.c_str());
  std::printf("dims     %lld x %lld x %lld\n", static_cast<long long>(v.dims[0]),
              static_cast<long long>(v.dims[1]), static_cast<long long>(v.dims[2]));
  std::printf("type     %s (%zu bytes)\n", std::string(scalar_name(v.type)).c_str(),
              volume.byte_size());
  std::printf("spacing  %g, %g, %g\n", v.spacing[0], v.spacing[1], v.spacing[2]);
  std::printf("format   %s\n", j["format"].get<std::string>().c_str());
  if (!header.series_uid.empty())
    std::printf("series   %s  %s\n", header.series_uid.c_str(), header.series_description.c_str());
  std::printf("origin   %g, %g, %g\n", v.origin[0], v.origin[1], v.origin[2]);
  std::printf(
      "world    origin %g, %g, %g; axes toward %s (LPS); direction columns (%g, %g, %g) "
      "(%g, %g, %g) (%g, %g, %g)\n",
      world.origin[0], world.origin[1], world.origin[2], axis_letters(world.direction).c_str(),
      world.direction[0], world.direction[3], world.direction[6], world.direction[1],
      world.direction[4], world.direction[7], world.direction[2], world.direction[5],
      world.direction[8]);
  if (header.rescaled)
    std::printf("rescale  value = stored x %g + %g (range and histogram in these units)\n",
                header.rescale_slope, header.rescale_intercept);
  std::printf("range    %g .. %g\n", lo, hi);
  std::printf("histogram\n");
  for (int b = 0; b < kBins; ++b)
    std::printf("  %12g .. %-12g %llu\n", lo + b * width, lo + (b + 1) * width,
                static_cast<unsigned long long>(hist[b]));
  if (auto_iso)
    std::printf("iso auto %.10g (Otsu's threshold: what extract --iso auto chooses)\n", *auto_iso);
  return 0;
}

// --- quality -------------------------------------------------------------------------------

int run_quality(const std::string& path, bool as_json, bool check_intersections,
                const std::string& reference) {
  const Mesh mesh = read_mesh(path);
  const QualityStats q = triangle_quality(mesh);
  const TopologyStats t = mesh_topology(mesh);
  json j;
  j["mesh"] = path;
  j["triangles"] = q.triangles;
  j["vertices"] = mesh.positions.size();
  j.update(quality_json(q));
  j.update(topology_json(t, false));
  j["edges"] = t.edges;
  j["unreferenced_vertices"] = t.unreferenced_vertices;
  std::optional<std::uint64_t> crossing;
  if (check_intersections) j["self_intersections"] = *(crossing = self_intersections(mesh).pairs);
  std::optional<SurfaceDistance> distance;
  if (!reference.empty()) {
    distance = surface_distance(read_mesh(reference), mesh);
    j["reference"] = reference;
    j["hausdorff_mean"] = distance->mean();
    j["hausdorff_max"] = distance->max();
    j["hausdorff_reference_to_mesh"] = {{"mean", distance->a_to_b.mean},
                                        {"max", distance->a_to_b.max},
                                        {"samples", distance->a_to_b.samples}};
    j["hausdorff_mesh_to_reference"] = {{"mean", distance->b_to_a.mean},
                                        {"max", distance->b_to_a.max},
                                        {"samples", distance->b_to_a.samples}};
  }
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("mesh                  %s\n", path.c_str());
  std::printf("vertices / triangles  %zu / %llu\n", mesh.positions.size(),
              static_cast<unsigned long long>(q.triangles));
  std::printf("radius ratio          min %.4g  q0.1%% %.4g  q1%% %.4g  mean %.4f  median %.4f\n",
              q.min, q.q001, q.q01, q.mean, q.median);
  std::printf("degenerate triangles  %llu\n", static_cast<unsigned long long>(q.degenerate));
  std::printf("boundary edges        %llu\n", static_cast<unsigned long long>(t.boundary_edges));
  std::printf("non-manifold          %llu edges, %llu vertices\n",
              static_cast<unsigned long long>(t.nonmanifold_edges),
              static_cast<unsigned long long>(t.nonmanifold_vertices));
  std::printf("orientation           %llu inconsistent edges\n",
              static_cast<unsigned long long>(t.inconsistently_oriented_edges));
  std::printf("euler / components    %lld / %llu\n", static_cast<long long>(t.euler),
              static_cast<unsigned long long>(t.components));
  std::printf("closed                %s\n", t.faces == 0 ? "n/a (no faces)"
                                            : t.closed   ? "yes"
                                                         : "no");
  std::printf(
      "watertight            cannot tell: a mesh file carries no volume box (isotile "
      "extract --stats can)\n");
  if (crossing)
    std::printf("self-intersections    %llu triangle pairs\n",
                static_cast<unsigned long long>(*crossing));
  if (distance)
    std::printf(
        "distance to reference mean %.4g  max %.4g (reference to mesh: mean %.4g max %.4g; "
        "mesh to reference: mean %.4g max %.4g)\n",
        distance->mean(), distance->max(), distance->a_to_b.mean, distance->a_to_b.max,
        distance->b_to_a.mean, distance->b_to_a.max);
  return 0;
}

// --- gl-info -------------------------------------------------------------------------------

int run_gl_info(bool as_json) {
#ifdef ISOTILE_HAVE_GL
  const isotile::gl::DeviceInfo& d = isotile::gl::device();  // InputError when there is none
  json j;
  j["platform"] = d.platform;
  j["vendor"] = d.vendor;
  j["renderer"] = d.renderer;
  j["version"] = d.version;
  j["glsl_version"] = d.glsl_version;
  j["software"] = d.software;
  j["memory_total_kib"] = d.memory_total_kib;
  j["memory_free_kib"] = d.memory_free_kib;
  j["max_shader_storage_block_bytes"] = d.max_ssbo_bytes;
  j["max_compute_work_group_count"] = d.max_compute_groups;
  j["max_geometry_output_vertices"] = d.max_gs_output_vertices;
  j["max_transform_feedback_interleaved_components"] = d.max_tf_interleaved;
  j["max_vertex_shader_storage_blocks"] = d.max_vertex_ssbo_blocks;
  j["max_geometry_shader_storage_blocks"] = d.max_geometry_ssbo_blocks;
  j["max_3d_texture_size"] = d.max_3d_texture;
  json backends = json::object();
  for (const BackendCaps& c : capabilities())
    backends[std::string(backend_name(c.backend))] =
        c.available ? (c.hardware ? "available (GPU)" : "available") : c.why_unavailable;
  j["backends"] = backends;
  j["auto"] = backend_name(resolve_backend({}));
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  for (const auto& [key, value] : j.items())
    std::printf("%-46s %s\n", key.c_str(),
                value.is_string() ? value.get<std::string>().c_str() : value.dump().c_str());
  return 0;
#else
  (void)as_json;
  throw InputError("this isotile was built without OpenGL (ISOTILE_GL=OFF)");
#endif
}

// One error line. Under MPI only rank 0 prints: an error outside the distributed run comes from
// the arguments, which every rank shares, and one inside it is agreed on by all ranks, with the
// failing rank named. An error only this rank has inside the run (not agreed) aborts the job, as
// the other ranks wait for this one.
int fail(const char* what, bool agreed) {
#ifdef ISOTILE_HAVE_MPI
  if (g_mpi) {
    if (g_distributed && !agreed && g_mpi->size > 1) {
      std::fprintf(stderr, "isotile: error: rank %d of %d: %s\n", g_mpi->rank, g_mpi->size, what);
      g_mpi->abort(1);
    }
    if (g_mpi->rank != 0) return 1;
  }
#else
  (void)agreed;
#endif
  std::fprintf(stderr, "isotile: error: %s\n", what);
  return 1;
}

extern "C" void on_signal(int sig) {
  remove_pending_temporaries();
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

}  // namespace

int main(int argc, char** argv) {
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  if (launched_by_mpi()) {
#ifdef ISOTILE_HAVE_MPI
    try {
      g_mpi.emplace(&argc, &argv);
    } catch (const isotile::Error& e) {
      std::fprintf(stderr, "isotile: error: %s\n", e.what());
      return 1;
    }
    if (g_mpi->rank != 0) g_quiet = true;
#else
    if (launcher_task_count() > 1) {
      std::fprintf(stderr,
                   "isotile: error: started by an MPI launcher with %ld tasks, but this isotile "
                   "was built without MPI (ISOTILE_MPI=OFF): every task would write the whole "
                   "mesh\n",
                   launcher_task_count());
      return 1;
    }
#endif
  }
#ifdef ISOTILE_HAVE_GL
  isotile::gl::register_gl_backends();
#endif

  // A fixed name: usage lines (and the man page generated from them) say "isotile", not argv[0].
  CLI::App app{"isotile: high-quality isosurface meshes from volumes on uniform grids", "isotile"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "isotile " ISOTILE_VERSION);
  // Every option's default in --help (and so in the man page), inherited by the subcommands.
  app.option_defaults()->always_capture_default();
  int threads = 0;
  app.add_option("--threads", threads, "Worker threads (0, the default: every core)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--quiet,-q", g_quiet, "No progress messages on stderr");

  ExtractArgs ex;
  auto* extract_cmd = app.add_subcommand("extract", "Extract an isosurface mesh from a volume");
  ex.in.add_to(*extract_cmd);
  extract_cmd
      ->add_option("-o,--output", ex.output,
                   "Output mesh: .ply (binary; --ascii for text), .obj, .stl (binary) or .off")
      ->required();
  extract_cmd->add_option(
      "--iso", ex.iso,
      "Isovalue; samples >= iso are inside. A finite number, or auto: Otsu's threshold of the "
      "samples' histogram, printed with their range. Required for files; fields default to "
      "their own (0; 0.5 for marschner-lobb)");
  extract_cmd->add_flag("--allow-empty", ex.allow_empty,
                        "Write the empty mesh (exit 0) when no pair of samples straddles the "
                        "isovalue, instead of failing with the samples' range");
  extract_cmd->add_option("--method", ex.method, "Extraction method")
      ->check(CLI::IsMember({"mc", "macet", "dc"}));
  extract_cmd->add_option("--backend", ex.backend, "Where to run it")
      ->check(CLI::IsMember({"cpu", "gs", "hp", "auto"}));
  extract_cmd->add_option("--stats", ex.stats,
                          "Write statistics as JSON to this file, any name ('-': stdout; "
                          "default: none)");
  extract_cmd->add_flag("--normals", ex.normals, "Compute vertex normals (PLY and OBJ store them)");
  extract_cmd->add_flag("--ascii", ex.ascii, "ASCII PLY instead of binary");
  extract_cmd
      ->add_option("--dc-solver", ex.dc_solver,
                   "Dual Contouring vertex placement: mass (mass point, best triangles), "
                   "particle (the paper's minimizer, 10 steps), qef (truncated SVD)")
      ->check(CLI::IsMember({"mass", "particle", "qef"}));
  extract_cmd
      ->add_option(
          "--dc-hermite", ex.dc_hermite,
          "Dual Contouring's Hermite data: central (central-difference normals, linear "
          "crossings; default) or eno (kink-aware crossings and one-sided normals: sharper "
          "edges and corners)")
      ->check(CLI::IsMember({"central", "eno"}));
  extract_cmd
      ->add_option("--dc-vertices", ex.dc_vertices,
                   "Dual Contouring's vertices: patch (one per surface patch of a cell: a "
                   "manifold mesh; default) or cell (one per cell, the paper's table: "
                   "non-manifold edges where a cell holds several sheets)")
      ->check(CLI::IsMember({"patch", "cell"}));
  extract_cmd
      ->add_option("--quality", ex.quality,
                   "Macet: fast (closed-form end-point push, default) or max (adds a local "
                   "search for the worst triangles; much slower)")
      ->check(CLI::IsMember({"fast", "max"}));
  extract_cmd
      ->add_option("--macet-relax", ex.macet_relax,
                   "Macet: move samples pinned in one-sample-thin features away from the "
                   "isovalue so that their crossings lie at least this far (edge lengths, "
                   "0 to 0.5, default 0: off); the surface moves by at most as much there and "
                   "their slivers go (docs/macet.md)")
      ->check(CLI::Validator(
          [](std::string& s) {
            char* end = nullptr;
            const double v = std::strtod(s.c_str(), &end);
            const bool ok = end != s.c_str() && *end == '\0' && v >= 0 && v < 0.5;
            return ok ? std::string() : "must be a number in [0, 0.5), got '" + s + "'";
          },
          "in [0, 0.5)"));
  extract_cmd->add_flag("--quads", ex.quads,
                        "Dual Contouring: keep quads (PLY and OBJ polygons) instead of splitting");
  extract_cmd->add_flag("--check-intersections", ex.check_intersections,
                        "Count self-intersecting triangle pairs (stats key self_intersections)");
  extract_cmd
      ->add_option("--simplify", ex.simplify,
                   "Simplify the mesh to this fraction of its faces (0 < R <= 1; 1: off), keeping "
                   "its topology, its border and well-shaped triangles (see `isotile simplify`)")
      ->check(
          CLI::Range(0.0, 1.0).description("in (0, 1]") &
          CLI::Validator([](std::string& s) { return std::stod(s) > 0 ? "" : "must be > 0"; }, ""));
  extract_cmd
      ->add_option("--frame", ex.frame,
                   "Mesh coordinates: world (default; the file's orientation, LPS for medical "
                   "images) or grid (origin + spacing x index, no direction cosines)")
      ->check(CLI::IsMember({"world", "grid"}));
  extract_cmd->add_option("--memory", ex.memory,
                          "Out of core: extract brick by brick, each brick's working set within "
                          "SIZE (e.g. 256MiB, 2GB), streaming the mesh to a binary PLY or STL "
                          "file identical to an in-core run (default: in core)");
  extract_cmd->add_option("--render", ex.render,
                          "Also draw the mesh to this PNG picture (as `isotile render MESH -o "
                          "PICTURE` with its defaults)");

  InputArgs info_in;
  bool info_json = false;
  auto* info_cmd =
      app.add_subcommand("info", "Describe a volume: dims, type, value range, histogram");
  info_in.add_to(*info_cmd);
  info_cmd->add_flag("--json", info_json, "Print JSON");

  std::string quality_path;
  bool quality_json_flag = false;
  auto* quality_cmd = app.add_subcommand(
      "quality", "Measure a mesh: radius ratios, boundary, manifoldness, Euler characteristic");
  quality_cmd->add_option("MESH", quality_path, "Mesh file (.ply, .obj, .stl, .off)")->required();
  quality_cmd->add_flag("--json", quality_json_flag, "Print JSON");
  bool quality_intersections = false;
  quality_cmd->add_flag("--check-intersections", quality_intersections,
                        "Count self-intersecting triangle pairs");
  std::string quality_reference;
  quality_cmd->add_option("--reference", quality_reference,
                          "Also measure the two-way sampled (Hausdorff) distance to this mesh "
                          "(.ply, .obj, .stl, .off), e.g. the input of a simplification (mesh "
                          "units; default: none)");

  SimplifyArgs sa;
  auto* simplify_cmd = app.add_subcommand(
      "simplify",
      "Simplify a mesh by edge collapses: fewer triangles, same topology and border, good shapes");
  simplify_cmd->add_option("IN", sa.input, "Mesh file (.ply, .obj, .stl, .off)")->required();
  simplify_cmd
      ->add_option("OUT", sa.output,
                   "Simplified mesh: .ply (binary; --ascii for text), .obj, .stl (binary) or .off")
      ->required();
  auto* ratio_opt =
      simplify_cmd->add_option("--ratio", sa.ratio, "Fraction of faces kept, in (0, 1]");
  auto* faces_opt =
      simplify_cmd->add_option("--faces", sa.faces, "Number of faces to keep (at least 1)");
  auto* error_opt = simplify_cmd->add_option(
      "--max-error", sa.max_error,
      "Simplify as far as the surface stays within E (mesh units) of the input: its "
      "vertices, edge midpoints and face centroids within E of the result (docs/simplify.md)");
  // Exactly one of the three is given: none has a default.
  for (CLI::Option* o : {ratio_opt, faces_opt, error_opt}) o->default_str("");
  ratio_opt->excludes(faces_opt)->excludes(error_opt);
  faces_opt->excludes(error_opt);
  simplify_cmd
      ->add_option("--min-quality", sa.min_quality,
                   "Radius ratio (0..1) below which collapses may not create triangles (default "
                   "0.3)")
      ->check(CLI::Range(0.0, 1.0));
  simplify_cmd->add_flag("--no-relax", sa.no_relax, "Skip the flips and tangential relaxation");
  simplify_cmd->add_flag("--ascii", sa.ascii, "ASCII PLY instead of binary");
  simplify_cmd->add_option("--stats", sa.stats,
                           "Write statistics as JSON to this file, any name ('-': stdout; "
                           "default: none)");

  std::string demo_output = "isotile-demo.ply";
  auto* demo_cmd = app.add_subcommand(
      "demo", "Extract the built-in demo (a 128^3 gyroid) and print its statistics");
  demo_cmd->add_option("-o,--output", demo_output,
                       "Where to write the demo mesh: .ply, .obj, .stl or .off");

  // Subcommand options may also come before the subcommand name.
  bool gl_info_json = false;
  auto* gl_info_cmd = app.add_subcommand(
      "gl-info", "Describe the OpenGL device the gs and hp backends would use, and its limits");
  gl_info_cmd->add_flag("--json", gl_info_json, "Print JSON");

  RenderArgs render_args;
  auto* render_cmd = add_render_command(app, render_args);

  for (auto* cmd : {extract_cmd, info_cmd, quality_cmd, simplify_cmd, demo_cmd, render_cmd})
    cmd->fallthrough();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
#ifdef ISOTILE_HAVE_MPI
    if (g_mpi && g_mpi->rank != 0) return e.get_exit_code() == 0 ? 0 : 2;
#endif
    // --help and --version exit 0; every usage error exits 2, whatever CLI11's own code is.
    if (app.exit(e) != 0) return 2;
    try {
      flush_stdout();
    } catch (const isotile::Error& io) {
      return fail(io.what(), false);
    }
    return 0;
  }

#ifdef ISOTILE_HAVE_MPI
  if (g_mpi && g_mpi->size > 1 && !(*extract_cmd && !ex.memory.empty())) {
    if (g_mpi->rank == 0)
      std::fprintf(stderr,
                   "isotile: error: under an MPI launcher only `extract --memory SIZE` runs "
                   "distributed; run other commands without mpirun\n");
    return 2;
  }
#endif

  std::optional<tbb::global_control> limit;
  if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, threads);
  tbb::task_scheduler_handle workers{tbb::attach{}};

  // Whatever went to standard output must have reached it: a failed write is exit 1.
  const auto finished = [](int rc) {
    if (rc == 0) flush_stdout();
    return rc;
  };
  const int rc = [&]() -> int {
    try {
      if (*extract_cmd) return finished(run_extract(ex));
      if (*info_cmd) return finished(run_info(info_in, info_json));
      if (*gl_info_cmd) return finished(run_gl_info(gl_info_json));
      if (*quality_cmd)
        return finished(
            run_quality(quality_path, quality_json_flag, quality_intersections, quality_reference));
      if (*simplify_cmd) return finished(run_simplify(sa));
      if (*render_cmd) return finished(run_render(render_args, g_quiet));
      if (*demo_cmd) {
        ExtractArgs d;
        d.in.input = "field:gyroid:128";
        d.output = demo_output;
        d.stats = "-";
        const int rc = finished(run_extract(d));
        if (rc == 0 && !g_quiet)
          std::fprintf(stderr, "isotile: demo mesh written to %s\n",
                       std::filesystem::absolute(demo_output).c_str());
        return rc;
      }
#ifdef ISOTILE_HAVE_MPI
    } catch (const isotile::AgreedError& e) {
      return fail(e.what(), true);
#endif
    } catch (const isotile::Error& e) {
      return fail(e.what(), false);
    } catch (const std::bad_alloc&) {
      return fail("out of memory", false);
    } catch (const std::exception& e) {
      return fail(e.what(), false);
    }
    return 0;
  }();

  // A known order at the end (docs/gl.md): TBB's workers joined, then the GL context and what was
  // made on it deleted, before exit() runs static destructors and the drivers' own exit handlers.
  limit.reset();
  tbb::finalize(workers, std::nothrow);
#ifdef ISOTILE_HAVE_GL
  isotile::gl::shutdown();
#endif
  return rc;
}
