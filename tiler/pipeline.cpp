#include "tiler/pipeline.h"

#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/field_distance.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/self_intersections.h"
#include "core/volume/procedural_fields.h"
#include "tiler/available_memory.h"
#include "tiler/brick_plan.h"
#include "tiler/gpu_report_json.h"
#include "tiler/source_histogram.h"
#include "tiler/volume_source.h"

namespace isotile {

namespace {

using Clock = std::chrono::steady_clock;
using Log = std::function<void(const std::string&)>;

// Gives the heap's free blocks back to the kernel. A process that keeps freed blocks for reuse
// (the CLI: mallopt in tiler/cli) would otherwise hold them through the next stage.
void return_freed_memory() {
#ifdef __GLIBC__
  malloc_trim(0);
#endif
}

// Frees the volume's samples and gives every freed block back to the kernel, so that the output
// file's pages (tmpfs or page cache) can take the volume's place instead of being fresh pages:
// on the development machines a 4 GiB volume's 3.4 GB mesh was written at 0.35 GB/s without the
// trim, 1.9 GB/s with it (docs/benchmarks.md, "In-core stages at scale").
void release_volume(Volume& volume) {
  volume = Volume();
  return_freed_memory();
}

std::string_view quality_name(MacetQuality q) {
  return q == MacetQuality::Max ? "max" : "fast";
}
std::string_view dc_vertices_name(DcVertices v) {
  return v == DcVertices::Cell ? "cell" : "patch";
}

std::string dims_text(const Index3& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

}  // namespace

TiledOptions tiled_options(const PipelineOptions& options, const ExtractOptions& extract,
                           MeshFormat format) {
  TiledOptions to;
  to.extract = extract;
  to.memory = parse_memory_size(options.memory);
  // A budget the machine cannot give is taken (the plan may need less), but said: bricks
  // planned to fill it could swap, or end in the OOM killer.
  if (const std::optional<AvailableMemory> available = available_memory();
      available && to.memory > available->most)
    say_warning(options.warn, "--memory " + options.memory + " is more than the " +
                                  bytes_text(available->most) +
                                  " of memory this process can have (" + available->said_by +
                                  "): bricks planned to fill it may not fit");
  to.allow_empty = options.allow_empty;
  to.format = format;
  to.simplify = options.simplify;
  // The radius-ratio statistics cost a fifth of a streamed run; only the stats report them.
  to.quality = options.stats || options.quality;
  if (options.ascii) throw InputError("--memory writes binary PLY or STL; drop --ascii");
  if (options.check_intersections)
    throw InputError(
        "--check-intersections needs the whole mesh in memory; drop --memory, or run "
        "`isotile quality --check-intersections` on the output");
  to.progress = options.progress;
  to.warn = options.warn;
  return to;
}

std::string tiled_summary(const TiledResult& r, bool simplified) {
  const std::int64_t bricks = r.plan.total();
  return (simplified
              ? "extracted " + std::to_string(r.triangles_extracted) + " triangles, simplified to "
              : std::string("extracted ")) +
         std::to_string(r.triangles) + " triangles, " + std::to_string(r.vertices) +
         " vertices in " + std::to_string(bricks) + (bricks == 1 ? " brick of " : " bricks of ") +
         std::to_string(r.plan.brick[0]) + "x" + std::to_string(r.plan.brick[1]) + "x" +
         std::to_string(r.plan.brick[2]) + " cells";
}

namespace {

// Out of core: brick by brick within options.memory, streamed into options.output.
PipelineResult run_tiled(const PipelineInput& input, const PipelineOptions& options,
                         const ExtractOptions& extract, MeshFormat format, const Log& log,
                         Clock::time_point t_total) {
  if (input.volume)
    throw InputError("an out-of-core run (memory) reads its input from a file; drop memory");
  TiledOptions to = tiled_options(options, extract, format);
  auto source = open_volume_source(input.path, input.raw, to.memory);
  check_grid_geometry(source->dims, source->spacing, source->origin, source->world, input.path);
  warn_coarse_positions(source->dims, source->spacing, source->origin,
                        options.world_frame ? source->world : std::nullopt, options.warn);
  if (options.world_frame) to.frame = mesh_frame(source->origin, source->world);
  // A GL backend asked for by name loads its programs and makes its pinned buffers (for a brick
  // of the budget's size at most) while the bricks are counted.
  prepare_backend(to.extract, source->type,
                  std::min(to.memory, checked_volume_bytes(source->type, source->dims)));
  StatsJson auto_iso;
  PipelineResult result;
  result.series_uid = source->series_uid;
  result.series_description = source->series_description;
  if (options.iso_auto) {
    log("reading " + input.path + " once for --iso auto's histogram");
    const ValueHistogram h = source_histogram(*source, to.memory, options.progress);
    auto_iso = choose_isovalue(h, to.extract.iso, log);
    result.auto_iso = to.extract.iso;
    result.range = std::pair(h.min, h.max);
  }
  log("extracting " + input.path + " (" + dims_text(source->dims) + " " +
      std::string(scalar_name(source->type)) + ") brick by brick within " + options.memory +
      (source->in_memory() ? " (this input cannot be read by region: read whole first)" : ""));
  const TiledResult r = extract_tiled(*source, to, options.output);
  log(tiled_summary(r, to.simplify < 1));
  result.iso = to.extract.iso;
  result.backend = r.backend;
  result.bricks = r.plan.total();
  result.triangles = r.triangles;
  result.vertices = r.vertices;
  result.triangles_extracted = to.simplify < 1 ? r.triangles_extracted : r.triangles;
  result.quality = r.quality;
  if (options.stats)
    result.stats = tiled_stats({.input = input.path,
                                .output = options.output,
                                .dims = source->dims,
                                .type = source->type,
                                .extract = &to.extract,
                                .auto_iso = auto_iso,
                                .result = &r,
                                .world_frame = to.frame.active,
                                .memory = to.memory,
                                .region_reads = !source->in_memory(),
                                .simplify = to.simplify,
                                .seconds_total = seconds_since(t_total)});
  return result;
}

}  // namespace

StatsJson choose_isovalue(const ValueHistogram& histogram, double& iso, const Log& log) {
  iso = otsu_isovalue(histogram);
  // Every number as the shortest text that reads back as it: ten digits printed 1 for
  // 1.0000000000753726, and the mesh of that printed value was another.
  if (log)
    log("--iso auto: " + number_text(iso) + " (Otsu's threshold; the samples range from " +
        number_text(histogram.min) + " to " + number_text(histogram.max) + ")");
  return {{"rule", "otsu"}, {"min", histogram.min}, {"max", histogram.max}};
}

StatsJson tiled_stats(const TiledStatsInput& in) {
  const ExtractOptions& options = *in.extract;
  const TiledResult& r = *in.result;
  StatsJson j;
  j["input"] = in.input;
  j["output"] = in.output;
  j["dims"] = in.dims;
  j["type"] = scalar_name(in.type);
  j["iso"] = options.iso;
  if (!in.auto_iso.is_null()) j["iso_auto"] = in.auto_iso;
  j["method"] = method_name(options.method);
  if (options.method == Method::Macet) {
    j["quality"] = quality_name(options.quality);
    j["macet_relax"] = options.macet_relax;
  }
  if (options.method == Method::DualContouring)
    j["dc_vertices"] = dc_vertices_name(options.dc_vertices);
  j["backend"] = backend_name(r.backend);
  j["backend_reason"] = choose_backend(options).reason;
  j["threads"] = stats_threads();
  j["frame"] = in.world_frame ? "world" : "grid";
  j["triangles"] = r.triangles;
  j["vertices"] = r.vertices;
  j.update(quality_json(r.quality));
  // Topology needs every edge's faces at once; a streamed run does not hold them. Its keys are
  // those of an in-core run (topology_json's), null rather than left out.
  const StatsJson in_core = topology_json(TopologyStats{}, false);
  for (const auto& item : in_core.items()) j[item.key()] = nullptr;
  j["bricks"] = r.plan.total();
  j["brick_cells"] = r.plan.brick;
  j["brick_grid"] = r.plan.count;
  j["bricks_extracted"] = r.bricks_extracted;
  j["memory_budget"] = in.memory;
  j["region_reads"] = in.region_reads;
  j["largest_brick_bytes"] = r.largest_brick_bytes;
  j["seconds"] = {
      {"count", r.seconds_count}, {"extract", r.seconds_extract}, {"total", in.seconds_total}};
  if (r.stages) {
    const TiledResult::Stages& st = *r.stages;
    j["seconds"]["stages"] = {{"read", st.read},   {"count", st.count},     {"extract", st.extract},
                              {"index", st.index}, {"records", st.records}, {"write", st.write}};
  }
  if (in.simplify < 1) {
    j["simplify"] = in.simplify;
    j["triangles_before"] = r.triangles_extracted;
    j["simplify_target_faces"] = r.simplify.target_faces;
    // Bricks are simplified with their seams locked, then the seams in cells of a grid shifted by
    // half a brick: the result depends on this plan (docs/simplify.md).
    j["simplify_brick_plan"] = {{"brick_cells", r.plan.brick},
                                {"brick_grid", r.plan.count},
                                {"seam_grid", r.seam_cells},
                                {"seam_parts", r.seam_parts}};
    j["simplify_collapses"] = r.simplify.collapses;
    j["simplify_split_vertices"] = r.simplify.split_vertices;
    j["simplify_unlinked_faces"] = r.simplify.unlinked_faces;
    // The distance needs the extracted and the simplified mesh whole.
    j["simplify_hausdorff_mean"] = nullptr;
    j["simplify_hausdorff_max"] = nullptr;
    j["seconds"]["seams"] = r.seconds_seams;
  }
  add_gpu_report(j, r.gpu);  // seconds.gl, upload_gbps, gl_program_cache over the bricks
  j["peak_rss_mb"] = peak_rss_mb();
  return j;
}

void check_pipeline_options(const PipelineOptions& options) {
  if (!(options.simplify > 0 && options.simplify <= 1))
    throw InputError("simplify must be in (0, 1] (1: off), got " + number_text(options.simplify));
  const ExtractOptions& eo = options.extract;
  check_method_options(eo);  // the CLI also refuses them given at their defaults
  // STL holds triangles only: --quads would be dropped without a word (checked here, where the
  // distributed run's checks pass too).
  if (eo.keep_quads && !options.output.empty() &&
      mesh_format_from_path(options.output) == MeshFormat::Stl)
    throw InputError(
        "--quads keeps quads in PLY, OBJ and OFF; STL holds triangles only: drop --quads");
  choose_backend(eo);  // InputError when the method cannot run on the backend asked for
}

ExtractOptions pipeline_extract_options(const PipelineInput& input,
                                        const PipelineOptions& options) {
  check_pipeline_options(options);
  ExtractOptions eo = options.extract;
  eo.cells = {};
  eo.progress = nullptr;
  eo.warn = options.warn;
  const std::optional<FieldSpec> field = parse_field_spec(input.path);
  if (options.iso && !options.iso_auto) {
    if (!std::isfinite(*options.iso))
      throw InputError("--iso must be a finite number or 'auto', got '" +
                       std::to_string(*options.iso) + "'");
    eo.iso = *options.iso;
  } else if (field && !options.iso_auto) {
    eo.iso = field_default_iso(field->kind);
  } else if (!options.iso_auto && input.volume) {
    // Samples in memory (an array from a front end): no file for `isotile info` to read.
    throw InputError("--iso is required: a number, or 'auto' for Otsu's threshold of the samples");
  } else if (!options.iso_auto) {
    throw InputError(
        "--iso is required for a volume file: a number, or 'auto' for Otsu's "
        "threshold of the samples (`isotile info " +
        input.path + "` shows their range and histogram)");
  }
  if (options.simplify < 1 && eo.keep_quads)
    throw InputError("--simplify gives triangles; drop --quads");
  return eo;
}

namespace {

PipelineResult run_pipeline_watched(const PipelineInput& input, const PipelineOptions& options) {
  const auto t_total = Clock::now();
  const Log log = [&](const std::string& line) {
    if (options.log) options.log(line);
  };
  const bool tiled = !options.memory.empty();
  if (tiled && options.output.empty())
    throw InputError("an out-of-core run (memory) streams the mesh into a file: give an output");
  // A bad output name fails before any time is spent reading: its folder, its kind (a device or
  // FIFO cannot take the streamed writer's positioned writes) and its extension.
  MeshFormat format = MeshFormat::Ply;
  if (!options.output.empty()) {
    check_output(options.output, tiled && options.simplify >= 1);
    format = mesh_output_format(options.output, options.ascii);
    if (!input.volume && !input.path.empty() && same_file(options.output, input.path))
      throw InputError("the output " + options.output +
                       " is the input's file (it would be replaced)");
  }
  // A GL backend asked for by name makes its context while the volume is read (or the bricks
  // counted) instead of before.
  start_backend(options.extract.backend);
  ExtractOptions eo = pipeline_extract_options(input, options);
  eo.progress = options.progress;
  BackendChoice choice = choose_backend(eo);
  const Backend backend = choice.backend;
  const std::optional<FieldSpec> field = parse_field_spec(input.path);
  const bool simplifying = options.simplify < 1;
  if (tiled) return run_tiled(input, options, eo, format, log, t_total);

  // In core.
  Volume volume;
  VolumeView view;
  double t_read = 0;
  auto t0 = Clock::now();
  if (input.volume) {
    // Samples in memory (an array) pass the checks a file's do in read_volume().
    view = *input.volume;
    checked_volume_bytes(view.type, view.dims);
    check_finite(view, input.path);
  } else {
    RawOptions raw = input.raw;
    raw.progress = options.progress;
    // Before the read: a volume that cannot fit is refused at once, not killed part-way through.
    if (const std::optional<SampleLayout> layout = in_core_layout(input.path, raw)) {
      if (const std::optional<AvailableMemory> available = available_memory())
        check_in_core_fits(in_core_bytes(*layout, eo), *available, input.path, options.warn);
      // A GL backend asked for by name loads its programs and makes its pinned buffers meanwhile.
      prepare_backend(eo, layout->type, layout->bytes);
    }
    log("reading " + input.path);
    volume = read_volume(input.path, raw);
    t_read = seconds_since(t0);
    // Only extract() and the repairs below read the samples; the rest of this run uses the
    // view's dims and frame, so its data pointer is cleared when the samples are released.
    view = volume.view();
  }
  check_grid_geometry(view.dims, view.spacing, view.origin, view.world, input.path);
  warn_coarse_positions(view.dims, view.spacing, view.origin,
                        options.world_frame ? view.world : std::nullopt, options.warn);
  if (!input.volume)
    log("read " + dims_text(view.dims) + " " + std::string(scalar_name(view.type)) + " in " +
        fmt_seconds(t_read));

  PipelineResult result;
  result.series_uid = volume.series_uid();
  result.series_description = volume.series_description();
  StatsJson auto_iso;
  if (options.iso_auto) {
    const ValueHistogram h = value_histogram(view);
    auto_iso = choose_isovalue(h, eo.iso, log);
    result.auto_iso = eo.iso;
    result.range = std::pair(h.min, h.max);
  } else if (options.range) {
    result.range = value_range(view);
  }
  log("extracting (" + std::string(method_name(eo.method)) + ", " +
      std::string(backend_name(backend)) + ", iso " + number_text(eo.iso) + ")");
  t0 = Clock::now();
  Mesh mesh = extract(view, eo, &choice);
  const double t_extract = seconds_since(t0);
  // No face: found from the mesh, at no cost to a run that has one (as out of core, where the
  // count pass finds it). The range, for the message, is a cheap pass.
  if (mesh.triangles.empty() && mesh.quads.empty() && !options.allow_empty)
    throw_no_surface(eo.iso, result.range ? *result.range : value_range(view));
  log("extracted " + std::to_string(mesh.triangles.size()) + " triangles, " +
      std::to_string(mesh.positions.size()) + " vertices in " + fmt_seconds(t_extract));
  result.triangles_extracted = mesh.triangles.size() + 2 * mesh.quads.size();

  // Dual Contouring's patch repairs (reported by the stats) are the last reader of the samples.
  std::optional<DcPatchRepairs> repairs;
  double t_repairs = 0;
  if (options.stats && eo.method == Method::DualContouring && eo.dc_vertices == DcVertices::Patch) {
    t0 = Clock::now();
    repairs = dual_contouring_patch_repairs(view, eo.iso);
    t_repairs = seconds_since(t0);
  }
  // Nothing below reads the samples, and simplification and the write both gain from their
  // memory; the time is counted in the stage that comes next.
  t0 = Clock::now();
  if (!input.volume) release_volume(volume);
  view.data = nullptr;
  const double t_release = seconds_since(t0);

  // The extracted mesh is kept past simplification only for the stats' distance measure.
  std::optional<Mesh> extracted;
  SimplifyStats sstats;
  double t_simplify = 0;
  if (simplifying) {
    log("simplifying to " + number_text(options.simplify) + " of the faces");
    t0 = Clock::now();
    SimplifyOptions so;
    so.ratio = options.simplify;
    so.min_quality = 0.3;
    so.relax = true;
    so.progress = options.progress;
    Mesh simplified = simplify(mesh, so, &sstats);
    t_simplify = seconds_since(t0) + t_release;
    log("simplified to " + std::to_string(simplified.triangles.size()) + " triangles in " +
        fmt_seconds(t_simplify));
    if (const std::string missed = target_missed(sstats); !missed.empty())
      say_warning(options.warn, missed);
    if (options.stats) extracted = std::move(mesh);
    mesh = std::move(simplified);
  }

  // Positions go out in the volume's world frame; the measures below stay in the grid frame (the
  // volume border is a box there), as a streamed run's do.
  const MeshFrame frame = options.world_frame ? mesh_frame(view) : MeshFrame{};
  std::optional<Mesh> world;  // the mesh in the world frame, when that is not the grid frame
  double t_write = 0;
  if (!options.output.empty()) {
    log("writing " + options.output);
    t0 = Clock::now();
    // The simplifier's freed memory would otherwise stay resident through the measures: peak RSS
    // 13.8 GB against 9.5 GB for 22M triangles simplified to a tenth with the stats.
    if (simplifying) return_freed_memory();
    double t_hook = 0;
    const Mesh* written = &mesh;
    if (frame.active) {
      world = mesh;
      apply_frame(frame, *world);
      written = &*world;
    }
    write_mesh(*written, options.output,
               {.format = format,
                .ascii = options.ascii,
                .write_normals = true,
                .progress = options.progress});
    if (options.written) {
      const auto t_h = Clock::now();
      options.written(*written);
      t_hook = seconds_since(t_h);
    }
    t_write = seconds_since(t0) - t_hook + (simplifying ? 0.0 : t_release);
  }

  result.iso = eo.iso;
  result.backend = choice.backend;
  result.triangles = mesh.triangles.size() + 2 * mesh.quads.size();
  result.vertices = mesh.positions.size();
  if (options.quality && !options.stats) result.quality = triangle_quality(mesh);
  if (options.stats) {
    t0 = Clock::now();
    const QualityStats q = triangle_quality(mesh);
    result.quality = q;
    const TopologyStats topo = mesh_topology(mesh, volume_border(view, eo.method));
    StatsJson& j = result.stats;
    j["input"] = input.path;
    j["output"] = options.output.empty() ? StatsJson(nullptr) : StatsJson(options.output);
    j["dims"] = view.dims;
    j["type"] = scalar_name(view.type);
    j["iso"] = eo.iso;
    if (!auto_iso.is_null()) j["iso_auto"] = auto_iso;
    j["method"] = method_name(eo.method);
    if (eo.method == Method::Macet) {
      j["quality"] = quality_name(eo.quality);
      j["macet_relax"] = eo.macet_relax;
    }
    j["backend"] = backend_name(choice.backend);
    j["backend_reason"] = choice.reason;
    j["threads"] = stats_threads();
    j["frame"] = frame.active ? "world" : "grid";
    j["triangles"] = result.triangles;
    j["vertices"] = result.vertices;
    j.update(quality_json(q));
    j.update(topology_json(topo, true));
    j["bricks"] = 1;
    if (eo.method == Method::DualContouring) {
      j["dc_vertices"] = dc_vertices_name(eo.dc_vertices);
      if (repairs) {
        j["dc_flipped_faces"] = repairs->flipped_faces;
        j["dc_border_cut_cells"] = repairs->border_cut_cells;
      }
    }
    if (options.check_intersections) j["self_intersections"] = self_intersections(mesh).pairs;
    if (extracted) {
      j["simplify"] = options.simplify;
      j.update(simplify_json(sstats, *extracted, mesh,
                             {1 / view.spacing[0], 1 / view.spacing[1], 1 / view.spacing[2]}));
    }
    if (field) {
      const FieldDistance d = field_distance(*field, mesh, view.origin, view.spacing);
      const bool none = mesh.positions.empty();  // no vertex: no distance
      j["distance_mean"] = none ? StatsJson(nullptr) : StatsJson(d.mean);
      j["distance_max"] = none ? StatsJson(nullptr) : StatsJson(d.max);
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
  }
  if (options.keep_mesh) {
    if (world) {
      result.mesh = std::move(*world);
    } else {
      if (frame.active) apply_frame(frame, mesh);
      result.mesh = std::move(mesh);
    }
  }
  return result;
}

}  // namespace

PipelineResult run_pipeline(const PipelineInput& input, const PipelineOptions& options) {
  // A GL backend asked for by name makes its context on a thread while the volume is read
  // (start_backend()). If that fails, a fraction of a second in, the run stops at its next report
  // with the backend's error, instead of after a read that may take minutes.
  const Backend asked = options.extract.backend;
  struct Watch {
    Progress* p;
    ~Watch() {
      if (p) p->set_stop_when({});
    }
  } watch{options.progress};
  if (watch.p) watch.p->set_stop_when([asked] { return !backend_start_failure(asked).empty(); });
  try {
    return run_pipeline_watched(input, options);
  } catch (const NoSurfaceError& e) {
    // --iso auto chose the isovalue: the way out is another method or an isovalue of one's own,
    // not --iso auto again.
    if (!options.iso_auto) throw;
    throw NoSurfaceError("no surface at iso " + number_text(e.iso) +
                             " (the isovalue --iso auto chose): " + e.finding +
                             "; choose another method or an isovalue with --iso, or --allow-empty "
                             "to write the empty mesh",
                         e.iso, e.range, e.finding, e.straddled);
  } catch (const Cancelled&) {
    if (std::string why = backend_start_failure(asked); !why.empty()) throw InputError(why);
    throw;
  }
}

}  // namespace isotile
