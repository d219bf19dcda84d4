// The `isotile._isotile` extension: NumPy arrays onto the library's views and meshes, and the
// library's calls with the GIL released; files through the library's pipeline (tiler/pipeline.h),
// the same run as the isotile program's. What users call, and the scikit-image conventions
// (axis order, level, winding), live in the pure-Python layer (python/isotile/__init__.py); this
// file only maps arrays and calls core.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/errors.h"
#include "core/extract/cell_mask.h"
#include "core/extract/cell_ranges.h"
#include "core/extract/extract.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/mesh/self_intersections.h"
#include "core/simplify/simplify.h"
#include "core/version.h"
#include "core/volume/finite_range.h"
#include "core/volume/volume_io.h"
#include "tiler/input_options.h"
#include "tiler/option_names.h"
#include "tiler/pipeline.h"
#include "tiler/source_histogram.h"
#include "tiler/stats_json.h"
#ifdef ISOTILE_PYTHON_GL
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#endif

namespace py = pybind11;
using namespace isotile;

namespace {

// The library's sample type for a NumPy dtype read in place; bool is read as uint8 (NumPy stores
// it as one byte, 0 or 1).
std::optional<ScalarType> scalar_type_of_dtype(const py::dtype& dt) {
  const char kind = dt.kind();
  const auto size = dt.itemsize();
  if (kind == 'b' && size == 1) return ScalarType::UInt8;
  if (kind == 'i') {
    if (size == 1) return ScalarType::Int8;
    if (size == 2) return ScalarType::Int16;
    if (size == 4) return ScalarType::Int32;
  }
  if (kind == 'u') {
    if (size == 1) return ScalarType::UInt8;
    if (size == 2) return ScalarType::UInt16;
    if (size == 4) return ScalarType::UInt32;
  }
  if (kind == 'f') {
    if (size == 4) return ScalarType::Float32;
    if (size == 8) return ScalarType::Float64;
  }
  return std::nullopt;
}

// A view of a 3-D array indexed [z, y, x] (axis 0 slowest in a C-ordered array), in place: the
// library's x is NumPy's axis 2. Strides must be non-negative multiples of the item size and the
// data aligned and in native byte order (the Python layer copies anything else first).
VolumeView view_of(const py::array& a, const Vec3d& spacing_xyz, const char* what) {
  if (a.ndim() != 3) throw py::value_error(std::string(what) + " must be a 3-D array");
  const std::optional<ScalarType> type = scalar_type_of_dtype(a.dtype());
  if (!type)
    throw py::type_error(std::string(what) + ": dtype " + py::str(a.dtype()).cast<std::string>() +
                         " cannot be read in place");
  if (a.dtype().byteorder() == '>')
    throw py::type_error(std::string(what) + " must be in native byte order");
  const auto item = static_cast<std::int64_t>(a.itemsize());
  if (reinterpret_cast<std::uintptr_t>(a.data()) % static_cast<std::uintptr_t>(item) != 0)
    throw py::value_error(std::string(what) + " is not aligned");
  VolumeView v;
  v.data = a.data();
  v.type = *type;
  for (int axis = 0; axis < 3; ++axis) {
    const int np_axis = 2 - axis;
    const auto stride = static_cast<std::int64_t>(a.strides(np_axis));
    if (stride < 0 || stride % item != 0)
      throw py::value_error(std::string(what) +
                            ": strides must be non-negative multiples of the item size");
    v.dims[axis] = static_cast<std::int64_t>(a.shape(np_axis));
    v.strides[axis] = stride / item;
  }
  v.spacing = spacing_xyz;
  v.box = {{0, 0, 0}, v.dims};
  v.global_dims = v.dims;
  return v;
}

// Runs `f` with at most `threads` worker threads (none: TBB's default) and without the GIL.
template <class F>
auto run_released(std::optional<int> threads, F&& f) {
  if (threads && *threads < 1) throw py::value_error("threads must be at least 1");
  py::gil_scoped_release release;
  if (threads) {
    // No more than TBB can start: beyond the cores it printed a warning of its own on stderr
    // ("The request for 2 workers is ignored"), past Python's warnings, and ran as many anyway.
    tbb::task_arena arena(std::min(*threads, tbb::info::default_concurrency()));
    return arena.execute(std::forward<F>(f));
  }
  return f();
}

// The library's warnings (core/progress.h), kept from whichever thread says them until the
// calling thread, holding the GIL, hands them to Python's warnings. With `handed`, the thread
// that says one waits until a watcher has issued it and called released() (extract's watcher
// issues them while the run goes on): a filter that makes it an error has cancelled the run by
// then, before the run can write its file.
class Warnings {
 public:
  explicit Warnings(bool handed = false) : handed_(handed) {}
  Warn sink() {
    return [this](const std::string& line) {
      std::unique_lock lock(mutex_);
      lines_.push_back(line);
      const std::uint64_t ticket = ++said_;
      if (handed_) released_cv_.wait(lock, [&] { return released_ >= ticket; });
    };
  }
  // Under the GIL: each line kept so far as a RuntimeWarning, attributed to the code that called
  // the isotile function (stack level 2: past the pure-Python layer). Where a warnings filter
  // makes them errors, the first one is raised (py::error_already_set) and the rest dropped.
  void issue() {
    std::vector<std::string> lines;
    {
      std::lock_guard lock(mutex_);
      lines.swap(lines_);
    }
    for (const std::string& line : lines)
      if (PyErr_WarnEx(PyExc_RuntimeWarning, line.c_str(), 2) < 0) throw py::error_already_set();
  }
  // Lets the threads waiting on the lines said so far go on (issued, or dropped after an error).
  void release() {
    {
      std::lock_guard lock(mutex_);
      released_ = said_;
    }
    released_cv_.notify_all();
  }

 private:
  const bool handed_;
  std::mutex mutex_;
  std::condition_variable released_cv_;
  std::vector<std::string> lines_;
  std::uint64_t said_ = 0, released_ = 0;
};

// What one extraction hands to Python: the arrays point into it, a capsule owns it.
struct Result {
  Mesh mesh;
  std::vector<float> values;
};

py::capsule owner_of(Result* r) {
  return py::capsule(r, [](void* p) { delete static_cast<Result*>(p); });
}

// (n, 3) float32 rows of `rows` (Vec3f), owned by `owner`.
py::array vec3_array(const std::vector<Vec3f>& rows, const py::capsule& owner) {
  const auto n = static_cast<py::ssize_t>(rows.size());
  return py::array(py::dtype::of<float>(), {n, py::ssize_t{3}},
                   {py::ssize_t{3 * sizeof(float)}, py::ssize_t{sizeof(float)}},
                   rows.empty() ? nullptr : rows.data()->data(), owner);
}

// (n, 3) faces or (n, 4) quads; int32 as scikit-image gives faces while the vertex count allows,
// else uint32.
template <class Row>
py::array index_array(const std::vector<Row>& rows, std::size_t vertices,
                      const py::capsule& owner) {
  constexpr auto width = static_cast<py::ssize_t>(std::tuple_size_v<Row>);
  const auto n = static_cast<py::ssize_t>(rows.size());
  const py::dtype dt =
      vertices <= static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())
          ? py::dtype::of<std::int32_t>()
          : py::dtype::of<std::uint32_t>();
  return py::array(
      dt, {n, width},
      {py::ssize_t{width * py::ssize_t{sizeof(std::uint32_t)}}, py::ssize_t{sizeof(std::uint32_t)}},
      rows.empty() ? nullptr : rows.data()->data(), owner);
}

Method parse_method(const std::string& s) {
  if (s == "mc") return Method::MarchingCubes;
  if (s == "macet") return Method::Macet;
  if (s == "dc") return Method::DualContouring;
  throw py::value_error("method must be mc, macet or dc, not '" + s + "'");
}

Backend parse_backend(const std::string& s) {
  for (int b = 0; b < kBackendCount; ++b)
    if (backend_name(static_cast<Backend>(b)) == s) return static_cast<Backend>(b);
  throw py::value_error("backend must be cpu, gs, hp or auto, not '" + s + "'");
}

// `whole`: the array the level is checked against (scikit-image takes the whole volume's range
// whatever the step; `volume` may be a strided view of it). The check and the extraction run in
// one call without the GIL, so that a call enters TBB's arena once.
py::tuple extract_arrays(const py::array& volume, const py::array& whole,
                         std::optional<double> level, const Vec3d& spacing_xyz,
                         const std::string& method, const std::string& quality,
                         const std::string& backend, bool normals, bool values,
                         const std::optional<py::array>& mask, std::optional<int> threads) {
  const VolumeView view = view_of(volume, spacing_xyz, "volume");
  // Positions are float32: a spacing whose grid they cannot hold is refused (the Python layer has
  // checked that it is finite and positive).
  check_position_range(view.dims, spacing_xyz, view.origin, std::nullopt, "volume");
  const VolumeView whole_view = view_of(whole, {1, 1, 1}, "volume");
  std::optional<VolumeView> mask_view;
  if (mask) {
    mask_view = view_of(*mask, spacing_xyz, "mask");
    if (mask_view->type != ScalarType::UInt8)
      throw py::type_error("mask must be a bool (or uint8) array");
  }
  ExtractOptions options;
  options.method = parse_method(method);
  options.backend = parse_backend(backend);
  options.normals = normals;
  if (quality != "fast" && quality != "max")
    throw py::value_error("quality must be fast or max, not '" + quality + "'");
  options.quality = quality == "max" ? MacetQuality::Max : MacetQuality::Fast;
  check_method_options(options);
  Warnings warnings;
  options.warn = warnings.sink();
  auto* result = new Result;
  py::capsule owner = owner_of(result);  // frees the result on any exception below
  enum class Level { Ok, NaN, OutOfRange } level_check = Level::Ok;
  run_released(threads, [&] {
    const auto [lo, hi] = finite_value_range(whole_view, "volume");
    // None: the middle of the data's range, as scikit-image takes it.
    options.iso = level ? *level : 0.5 * (lo + hi);
    if (std::isnan(options.iso)) {
      level_check = Level::NaN;
      return 0;
    }
    if (options.iso < lo || options.iso > hi) {
      level_check = Level::OutOfRange;
      return 0;
    }
    result->mesh = extract(view, options);
    if (mask_view) result->mesh = keep_masked_cells(result->mesh, view, *mask_view);
    if (values)
      result->values = vertex_cell_ranges(view, result->mesh, mask_view ? &*mask_view : nullptr);
    return 0;
  });
  warnings.issue();
  // scikit-image's messages.
  if (level_check == Level::NaN) throw py::value_error("Surface level must be a number, not NaN.");
  if (level_check == Level::OutOfRange)
    throw py::value_error("Surface level must be within volume data range.");
  const Mesh& m = result->mesh;
  py::object out_normals = py::none(), out_values = py::none();
  if (normals) out_normals = vec3_array(m.normals, owner);
  if (values)
    out_values =
        py::array(py::dtype::of<float>(), {static_cast<py::ssize_t>(result->values.size())},
                  {py::ssize_t{sizeof(float)}},
                  result->values.empty() ? nullptr : result->values.data(), owner);
  return py::make_tuple(vec3_array(m.positions, owner),
                        index_array(m.triangles, m.positions.size(), owner), out_normals,
                        out_values);
}

Mesh mesh_of_arrays(const py::array& vertices, const py::array& faces, const py::object& quads,
                    const py::object& normals);

py::object quality_of(const py::array& vertices, const py::array& faces, bool check_intersections,
                      std::optional<int> threads) {
  const Mesh mesh = mesh_of_arrays(vertices, faces, py::none(), py::none());
  QualityStats q;
  TopologyStats t;
  std::optional<std::uint64_t> crossing;
  run_released(threads, [&] {
    q = triangle_quality(mesh);
    t = mesh_topology(mesh);
    if (check_intersections) crossing = self_intersections(mesh).pairs;
    return 0;
  });
  // The keys and values of `isotile quality --json`, built by the same function.
  return py::module_::import("json").attr("loads")(mesh_measures_json(mesh, q, t, crossing).dump());
}

py::tuple simplify_arrays(const py::array& vertices, const py::array& faces, double ratio,
                          std::uint64_t target_faces, double max_error, double min_quality,
                          bool relax, std::optional<int> threads) {
  const Mesh mesh = mesh_of_arrays(vertices, faces, py::none(), py::none());
  SimplifyOptions o;
  o.ratio = ratio;
  o.faces = target_faces;
  o.max_error = max_error;
  o.min_quality = min_quality;
  o.relax = relax;
  auto* result = new Result;
  py::capsule owner = owner_of(result);
  SimplifyStats stats;
  run_released(threads, [&] {
    result->mesh = simplify(mesh, o, &stats);
    return 0;
  });
  // A face target missed by more than a tenth, as extract's warnings are said: a RuntimeWarning
  // at the caller's line (isotile.simplify's caller: two levels up). Not where max_error, the
  // other target, stopped it first.
  if (const std::string missed = target_missed(stats); !missed.empty() && max_error == 0)
    if (PyErr_WarnEx(PyExc_RuntimeWarning, missed.c_str(), 2) != 0) throw py::error_already_set();
  return py::make_tuple(vec3_array(result->mesh.positions, owner),
                        index_array(result->mesh.triangles, result->mesh.positions.size(), owner));
}

// For tests/benchmarks/bench_python.py: the library calls marching_cubes makes (the samples'
// check and range, extract, values) timed inside C++ on the same view, without the Python layer or
// the arrays' wrapping, so that the binding's overhead can be measured in the same process, and
// what each call costs. Per run, seconds of wall clock then of the process's CPU time (which the
// load of a shared machine changes little): (checks, extract(), values) each.
using StepTimes = std::array<double, 6>;
std::vector<StepTimes> time_library_calls(const py::array& volume, double level,
                                          const std::string& method, bool normals, int threads,
                                          int repeats) {
  const VolumeView view = view_of(volume, {1, 1, 1}, "volume");
  ExtractOptions options;
  options.method = parse_method(method);
  options.backend = Backend::Cpu;
  options.iso = level;
  options.normals = normals;
  std::vector<StepTimes> out;
  run_released(threads, [&] {
    struct Now {
      std::chrono::steady_clock::time_point wall = std::chrono::steady_clock::now();
      std::clock_t cpu = std::clock();  // the process's CPU time, all threads
    };
    const auto wall = [](const Now& a, const Now& b) {
      return std::chrono::duration<double>(b.wall - a.wall).count();
    };
    const auto cpu = [](const Now& a, const Now& b) {
      return static_cast<double>(b.cpu - a.cpu) / CLOCKS_PER_SEC;
    };
    for (int r = 0; r < repeats; ++r) {
      const Now t0;
      const auto range = finite_value_range(view, "volume");
      const Now t1;
      Mesh mesh = extract(view, options);
      const Now t2;
      const std::vector<float> values = vertex_cell_ranges(view, mesh);
      const Now t3;
      if (mesh.triangles.empty() || values.size() != mesh.positions.size() || range.first > level)
        throw InputError("no surface");
      out.push_back(
          {wall(t0, t1), wall(t1, t2), wall(t2, t3), cpu(t0, t1), cpu(t1, t2), cpu(t2, t3)});
    }
    return 0;
  });
  return out;
}

// --- files, volumes and the pipeline (isotile.extract, read_volume, read_mesh, write_mesh) -----

// A volume read by the library (isotile.read_volume): its samples stay in the library's buffer
// and are shown to NumPy in place; extract() hands the same view back to the pipeline, so that
// extract(read_volume(path)) and extract(path) make the same mesh.
struct VolumeHandle {
  Volume volume;
  std::string name;  // the path it was read from
};

// An empty text is None's stand-in nowhere: as the CLI's empty --memory "$MEM" or --spacing
// "$S", it would run in core, write nothing or take the file's value without a word.
std::string not_empty(std::string v, const char* key) {
  if (v.empty()) throw py::value_error(std::string(key) + " must not be empty (None: not given)");
  return v;
}

// The raw-input options as the CLI takes them (text: "256,256,128", "uint16", ...), with the
// CLI's checks and messages (tiler/input_options.h).
RawOptions raw_options_of(const py::dict& o) {
  const auto text = [&](const char* key) {
    return o.contains(key) && !o[key].is_none()
               ? not_empty(py::str(o[key]).cast<std::string>(), key)
               : std::string();
  };
  RawOptions raw = parse_input_text({.dims = text("dims"),
                                     .type = text("type"),
                                     .spacing = text("spacing"),
                                     .origin = text("origin"),
                                     .endian = text("endian")},
                                    "");
  raw.series = text("series");
  return raw;
}

std::shared_ptr<VolumeHandle> read_volume_py(const std::string& path, const py::dict& raw_text) {
  const RawOptions raw = raw_options_of(raw_text);
  auto handle = std::make_shared<VolumeHandle>();
  handle->name = path;
  {
    py::gil_scoped_release release;
    handle->volume = read_volume(path, raw);
  }
  return handle;
}

// The samples [z, y, x] (x fastest, as read), read-only, kept alive by the handle.
py::array samples_of(const py::object& self) {
  const auto& h = self.cast<const VolumeHandle&>();
  const VolumeView v = h.volume.view();
  const auto item = static_cast<py::ssize_t>(scalar_size(v.type));
  const char* format = nullptr;
  switch (v.type) {
    case ScalarType::Int8:
      format = "i1";
      break;
    case ScalarType::UInt8:
      format = "u1";
      break;
    case ScalarType::Int16:
      format = "i2";
      break;
    case ScalarType::UInt16:
      format = "u2";
      break;
    case ScalarType::Int32:
      format = "i4";
      break;
    case ScalarType::UInt32:
      format = "u4";
      break;
    case ScalarType::Float32:
      format = "f4";
      break;
    case ScalarType::Float64:
      format = "f8";
      break;
  }
  py::array a(py::dtype(format), {v.dims[2], v.dims[1], v.dims[0]},
              {item * v.strides[2], item * v.strides[1], item * v.strides[0]}, v.data, self);
  a.attr("flags").attr("writeable") = false;
  return a;
}

// An option's value as T, or a ValueError naming the option and what it takes (pybind11's own
// "Unable to cast Python instance to C++ type" names neither).
template <class T>
T option_as(const py::handle& value, const char* key, const char* takes) {
  try {
    return value.cast<T>();
  } catch (const py::cast_error&) {
    throw py::value_error(std::string(key) + " must be " + takes + ", not " +
                          py::repr(value).cast<std::string>());
  }
}

// The options of isotile.extract (its keywords, checked by the library).
PipelineOptions pipeline_options_of(const py::dict& o) {
  const auto has = [&](const char* key) { return o.contains(key) && !o[key].is_none(); };
  const auto str = [&](const char* key, const char* fallback) {
    return has(key) ? o[key].cast<std::string>() : std::string(fallback);
  };
  const auto flag = [&](const char* key) { return has(key) && o[key].cast<bool>(); };
  const auto pick = [](const std::string& v, const char* what,
                       std::initializer_list<const char*> choices) {
    std::string list;
    for (const char* c : choices) {
      if (v == c) return v;
      list += (list.empty() ? "" : ", ") + std::string(c);
    }
    throw py::value_error(std::string(what) + " must be one of " + list + ", not '" + v + "'");
  };
  PipelineOptions p;
  ExtractOptions& e = p.extract;
  e.method = parse_method(str("method", "mc"));
  e.backend = parse_backend(str("backend", "auto"));
  e.normals = flag("normals");
  const std::string solver =
      pick(str("dc_solver", "mass"), "dc_solver", {"mass", "particle", "qef"});
  e.dc_solver = solver == "particle" ? DcSolver::Particle
                : solver == "qef"    ? DcSolver::Qef
                                     : DcSolver::MassPoint;
  e.dc_hermite = pick(str("dc_hermite", "central"), "dc_hermite", {"central", "eno"}) == "eno"
                     ? DcHermite::Eno
                     : DcHermite::Central;
  e.dc_vertices = pick(str("dc_vertices", "patch"), "dc_vertices", {"patch", "cell"}) == "cell"
                      ? DcVertices::Cell
                      : DcVertices::Patch;
  e.quality = pick(str("quality", "fast"), "quality", {"fast", "max"}) == "max"
                  ? MacetQuality::Max
                  : MacetQuality::Fast;
  e.macet_relax =
      has("macet_relax") ? option_as<double>(o["macet_relax"], "macet_relax", "a number") : 0.0;
  e.keep_quads = flag("quads");
  if (has("iso")) {
    const py::object iso = o["iso"];
    if (py::isinstance<py::str>(iso)) {
      if (iso.cast<std::string>() != "auto")
        throw py::value_error("iso must be a number or 'auto', not '" + iso.cast<std::string>() +
                              "'");
      p.iso_auto = true;
    } else {
      p.iso = option_as<double>(iso, "iso", "a number or 'auto'");
    }
  }
  p.world_frame = pick(str("frame", "world"), "frame", {"world", "grid"}) == "world";
  p.simplify = has("simplify") ? option_as<double>(o["simplify"], "simplify", "a number") : 1.0;
  p.check_intersections = flag("check_intersections");
  p.allow_empty = flag("allow_empty");
  if (has("memory")) {
    const py::object m = o["memory"];
    p.memory = py::isinstance<py::str>(m)
                   ? not_empty(m.cast<std::string>(), "memory")
                   : std::to_string(option_as<std::uint64_t>(
                         m, "memory", "a byte count (an int above 0) or a size such as '256MiB'"));
  }
  if (has("output")) p.output = not_empty(py::str(o["output"]).cast<std::string>(), "output");
  p.ascii = flag("ascii");
  p.stats = !o.contains("stats") || o["stats"].cast<bool>();
  return p;
}

// Progress and cancel between the library's threads and Python: the library's callback takes
// the GIL, looks for a pending signal (Ctrl-C) and calls the user's callable; either's exception
// is kept and the run cancelled. While the run goes on in a thread of its own, the calling thread
// (Python's main thread, the only one that runs signal handlers) looks for signals every 20 ms,
// so that Ctrl-C cancels the run within a fraction of a second whichever thread reports.
struct ProgressBridge {
  py::object callable;                         // None: only signals are watched
  std::optional<py::error_already_set> error;  // under the GIL
  bool declined = false;                       // the callable returned a false value (not None)
};

py::object make_mesh_tuple(Mesh&& mesh) {
  auto* result = new Result;
  result->mesh = std::move(mesh);
  py::capsule owner = owner_of(result);
  const Mesh& m = result->mesh;
  py::object normals = py::none();
  if (!m.normals.empty()) normals = vec3_array(m.normals, owner);
  return py::make_tuple(vec3_array(m.positions, owner),
                        index_array(m.triangles, m.positions.size(), owner),
                        index_array(m.quads, m.positions.size(), owner), normals);
}

// SIGTERM and SIGHUP (timeout(1), kill, a batch scheduler, a closed terminal) end a Python process
// at once where nothing handles them, and a run's temporary was left behind (out of core, one of
// the mesh's size). While runs last, the signals that Python left at their default action remove
// the temporaries first and then take it; a handler set from Python (signal.signal) is left
// alone. Ctrl-C is Python's KeyboardInterrupt, which cancels the run (ProgressBridge).
class TemporariesOnSignals {
 public:
  TemporariesOnSignals() {
    std::lock_guard lock(mutex_);
    if (runs_++ > 0) return;
    for (int i = 0; i < 2; ++i) {
      struct sigaction current {};
      ours_[i] = ::sigaction(kSignals[i], nullptr, &current) == 0 &&
                 current.sa_handler == SIG_DFL &&
                 std::signal(kSignals[i], remove_temporaries_and_reraise) != SIG_ERR;
    }
  }
  ~TemporariesOnSignals() {
    std::lock_guard lock(mutex_);
    if (--runs_ > 0) return;
    for (int i = 0; i < 2; ++i) {
      struct sigaction current {};
      if (ours_[i] && ::sigaction(kSignals[i], nullptr, &current) == 0 &&
          current.sa_handler == remove_temporaries_and_reraise)
        std::signal(kSignals[i], SIG_DFL);
      ours_[i] = false;
    }
  }
  TemporariesOnSignals(const TemporariesOnSignals&) = delete;
  TemporariesOnSignals& operator=(const TemporariesOnSignals&) = delete;

 private:
  static constexpr int kSignals[2] = {SIGTERM, SIGHUP};
  static inline std::mutex mutex_;
  static inline int runs_ = 0;
  static inline bool ours_[2] = {};
};

// Runs the pipeline on `source` (a path, a VolumeHandle, or a 3-D array [z, y, x] with spacing,
// origin and direction in x, y, z). Returns (mesh tuple or None, stats JSON text or None).
py::tuple run_pipeline_py(const py::object& source, const py::dict& options,
                          const py::object& progress, std::optional<int> threads) {
  if (threads && *threads < 1) throw py::value_error("threads must be at least 1");
  PipelineInput input;
  VolumeView view;
  py::object keep_alive = source;  // the samples stay referenced through the run
  if (py::isinstance<py::str>(source)) {
    input.path = source.cast<std::string>();
    input.raw = raw_options_of(options);
  } else if (py::isinstance<VolumeHandle>(source)) {
    const auto& h = source.cast<const VolumeHandle&>();
    view = h.volume.view();
    input.path = h.name;
    input.volume = &view;
  } else {
    const py::array a = source.cast<py::array>();
    const auto triple = [&](const char* key, Vec3d fallback) {
      if (!options.contains(key) || options[key].is_none()) return fallback;
      if (py::isinstance<py::str>(options[key])) {  // the CLI's text "x,y,z", read as for a path
        const std::string t = not_empty(options[key].cast<std::string>(), key);
        const bool spacing = std::string_view(key) == "spacing";
        InputText text;
        (spacing ? text.spacing : text.origin) = t;
        const RawOptions r = parse_input_text(text, "");
        if (const auto& v = spacing ? r.spacing : r.origin) return *v;
      }
      const auto v = option_as<std::vector<double>>(options[key], key, "three numbers");
      if (v.size() != 3) throw py::value_error(std::string(key) + " must be three numbers");
      return Vec3d{v[0], v[1], v[2]};
    };
    view = view_of(a, triple("spacing", {1, 1, 1}), "source");
    view.origin = triple("origin", {0, 0, 0});
    if (options.contains("direction") && !options["direction"].is_none()) {
      const auto d = option_as<std::vector<std::vector<double>>>(options["direction"], "direction",
                                                                 "a 3x3 matrix");
      if (d.size() != 3 || d[0].size() != 3 || d[1].size() != 3 || d[2].size() != 3)
        throw py::value_error("direction must be a 3x3 matrix");
      WorldFrame w{view.origin, {}};
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) w.direction[3 * r + c] = d[r][c];
      view.world = w;
    }
    input.path = options.contains("name") ? options["name"].cast<std::string>() : "array";
    input.volume = &view;
    keep_alive = a;
  }
  PipelineOptions po = pipeline_options_of(options);

  ProgressBridge bridge;
  if (!progress.is_none()) bridge.callable = progress;
  Progress reporter([&bridge](const ProgressUpdate& u) {
    py::gil_scoped_acquire gil;
    if (bridge.error || bridge.declined) return false;
    if (PyErr_CheckSignals() != 0) {  // on the main thread only; the watcher below covers others
      bridge.error.emplace();
      return false;
    }
    if (!bridge.callable) return true;
    try {
      const py::object go =
          bridge.callable(std::string(stage_name(u.stage)), u.brick, u.bricks, u.fraction);
      // Any false object cancels, as Python's `if` takes it, but None: a callable that returns
      // nothing (one that prints, or logs) means to watch, and cancelled at its first call.
      if (!go.is_none()) {
        const int truth = PyObject_IsTrue(go.ptr());
        if (truth < 0) throw py::error_already_set();
        if (truth == 0) bridge.declined = true;
      }
    } catch (py::error_already_set& e) {
      bridge.error.emplace(std::move(e));
    }
    return !bridge.error && !bridge.declined;
  });
  po.progress = &reporter;
  // Issued while the run goes on (the watcher below), so that a long run's warning is seen when
  // it is said; a filter that makes them errors cancels the run before it writes its file (the
  // thread that says one waits for the watcher).
  Warnings warnings(true);
  po.warn = warnings.sink();
  const auto issue_warnings = [&] {
    if (bridge.error) return;
    try {
      warnings.issue();
    } catch (py::error_already_set& e) {
      bridge.error.emplace(std::move(e));
    }
  };

  PipelineResult result;
  std::exception_ptr failure;
  const TemporariesOnSignals temporaries_on_signals;
  {
    py::gil_scoped_release release;
    std::mutex mutex;
    std::condition_variable cv;
    bool done = false;
    std::thread worker([&] {
      try {
        // The process's limit (not an arena's), so that the stats' "threads" says it, as the
        // CLI's --threads does.
        std::optional<tbb::global_control> limit;
        if (threads) limit.emplace(tbb::global_control::max_allowed_parallelism, *threads);
        result = run_pipeline(input, po);
      } catch (...) {
        failure = std::current_exception();
      }
      std::lock_guard lock(mutex);
      done = true;
      cv.notify_all();
    });
    std::unique_lock lock(mutex);
    while (!cv.wait_for(lock, std::chrono::milliseconds(20), [&] { return done; })) {
      lock.unlock();
      {
        py::gil_scoped_acquire gil;
        if (!bridge.error && PyErr_CheckSignals() != 0) bridge.error.emplace();
        issue_warnings();
        if (bridge.error) reporter.cancel();
        warnings.release();  // after the cancel, so that the run sees it
      }
      lock.lock();
    }
    lock.unlock();
    worker.join();
  }
  issue_warnings();  // those said after the watcher's last look
  // A Ctrl-C that came after the run wrote its file (it replaced the one before) leaves the new
  // file: removing it would lose both.
  if (bridge.error) throw std::move(*bridge.error);
  if (failure) std::rethrow_exception(failure);  // Cancelled (declined) included
  py::object mesh = py::none();
  if (po.memory.empty()) mesh = make_mesh_tuple(std::move(result.mesh));
  py::object stats = py::none();
  if (po.stats) stats = py::str(result.stats.dump());
  return py::make_tuple(mesh, stats);
}

// A face's corner as a vertex index, or a ValueError naming the row and what is wrong with it.
// Unsigned indices are read as such: uint64 ones past 2^63 were "vertex -1" once made int64.
template <class Index>
std::uint32_t vertex_index(Index idx, py::ssize_t vertices, const std::string& row, py::ssize_t i) {
  if constexpr (std::is_signed_v<Index>)
    if (idx < 0)
      throw py::value_error(row + " " + std::to_string(i) + " refers to vertex " +
                            std::to_string(idx) + ": indices count from 0");
  if (static_cast<std::uint64_t>(idx) >= static_cast<std::uint64_t>(vertices))
    throw py::value_error(row + " " + std::to_string(i) + " refers to vertex " +
                          std::to_string(idx) + ", past the " + std::to_string(vertices) +
                          " vertices");
  return static_cast<std::uint32_t>(idx);
}

// `a` as a C-ordered array of T, converted by NumPy. Only arrays of numbers (bool, integers,
// floats) are taken: NumPy would also parse strings and drop complex numbers' imaginary parts.
// The conversion's own errors (MemoryError) come out as they are, where pybind11's ensure()
// swallowed them (a null array: read as data, a crash). A float64 past float32's range becomes
// inf without NumPy's overflow warning (under warnings made errors, that warning was the error
// raised): the caller's check names it.
template <class T>
py::array_t<T, py::array::forcecast | py::array::c_style> numbers_as(const py::array& a,
                                                                     const std::string& what) {
  const char kind = a.dtype().kind();
  if (kind != 'b' && kind != 'i' && kind != 'u' && kind != 'f')
    throw py::type_error(what + " must be an array of real numbers, not " +
                         a.dtype().attr("name").cast<std::string>());
  const py::object quiet = py::module_::import("numpy").attr("errstate")(
      py::arg("over") = "ignore", py::arg("invalid") = "ignore");
  quiet.attr("__enter__")();
  try {
    // Its constructor, unlike ensure(), throws error_already_set on failure.
    py::array_t<T, py::array::forcecast | py::array::c_style> converted(a);
    quiet.attr("__exit__")(py::none(), py::none(), py::none());
    return converted;
  } catch (...) {
    quiet.attr("__exit__")(py::none(), py::none(), py::none());
    throw;
  }
}

// A mesh from arrays (vertices (V, 3), triangles (F, 3), quads (Q, 4) or None, normals (V, 3)
// or None), for every function that takes one (quality, simplify, write_mesh): copied, as Mesh
// owns its arrays. Positions that are not finite (NaN, inf, or float64 past float32's range)
// are refused here, as every mesh file reader refuses them: quality measured them as
// degenerate triangles.
Mesh mesh_of_arrays(const py::array& vertices, const py::array& faces, const py::object& quads,
                    const py::object& normals) {
  Mesh mesh;
  const auto rows = [](const py::array& a, int width, const char* what) {
    if (a.ndim() != 2 || a.shape(1) != width)
      throw py::value_error(std::string(what) + " must be an (N, " + std::to_string(width) +
                            ") array");
  };
  rows(vertices, 3, "vertices");
  const auto v = numbers_as<float>(vertices, "vertices");
  mesh.positions.resize(static_cast<std::size_t>(v.shape(0)));
  std::copy_n(v.data(), 3 * v.shape(0),
              mesh.positions.empty() ? nullptr : mesh.positions[0].data());
  check_finite_positions("vertices", mesh.positions);
  const auto indices = [&](const py::array& a, int width, const char* what, auto& out) {
    rows(a, width, what);
    if (a.size() > 0 && a.dtype().kind() != 'i' && a.dtype().kind() != 'u')
      throw py::type_error(std::string(what) + " must be an integer array");
    const auto read = [&](auto type) {
      using Index = decltype(type);
      const auto f = numbers_as<Index>(a, what);
      out.resize(static_cast<std::size_t>(f.shape(0)));
      for (py::ssize_t i = 0; i < f.shape(0); ++i)
        for (int c = 0; c < width; ++c)
          out[i][c] =
              vertex_index(f.data()[i * width + c], v.shape(0), std::string(what) + " row", i);
    };
    if (a.dtype().kind() == 'u') {
      read(std::uint64_t{});
    } else {
      read(std::int64_t{});
    }
  };
  indices(faces, 3, "faces", mesh.triangles);
  if (!quads.is_none()) indices(quads.cast<py::array>(), 4, "quads", mesh.quads);
  if (!normals.is_none()) {
    const py::array na = normals.cast<py::array>();
    rows(na, 3, "normals");
    if (na.shape(0) != v.shape(0)) throw py::value_error("normals must have one row per vertex");
    const auto n = numbers_as<float>(na, "normals");
    mesh.normals.resize(mesh.positions.size());
    std::copy_n(n.data(), 3 * n.shape(0), mesh.normals.empty() ? nullptr : mesh.normals[0].data());
    for (std::size_t i = 0; i < mesh.normals.size(); ++i)
      for (const float c : mesh.normals[i])
        if (!std::isfinite(c))
          throw py::value_error(
              "normals: row " + std::to_string(i) + " has a value that is not a finite number (" +
              std::to_string(c) +
              (std::isinf(c) ? ": infinite, or past float32's largest, 3.4e38" : "") + ")");
  }
  return mesh;
}

void write_mesh_py(const py::array& vertices, const py::array& faces, const py::object& quads,
                   const py::object& normals, const std::string& path, bool ascii) {
  const Mesh mesh = mesh_of_arrays(vertices, faces, quads, normals);
  py::gil_scoped_release release;
  write_mesh(mesh, path, {.format = std::nullopt, .ascii = ascii, .write_normals = true});
}

py::object read_mesh_py(const std::string& path) {
  Mesh mesh;
  {
    py::gil_scoped_release release;
    mesh = read_mesh(path);
  }
  return make_mesh_tuple(std::move(mesh));
}

}  // namespace

// A library message in Python's terms: the CLI's options (--macet-relax, --iso auto,
// --allow-empty) become the keywords that say the same (macet_relax, iso="auto",
// allow_empty=True).
std::string in_python_terms(std::string message) {
  // Longest first: "--iso auto" before "--iso".
  static const std::pair<std::string_view, std::string_view> kTerms[] = {
      {"--iso auto", "iso=\"auto\""},
      {"--allow-empty", "allow_empty=True"},
      // Out of core a run needs a file to stream into as well.
      {"give --memory SIZE", "give memory=\"SIZE\" and output=\"FILE\""},
      {"--method macet", "method=\"macet\""},
      {"--method dc", "method=\"dc\""},
      {"--method mc", "method=\"mc\""},
      {"--dims X,Y,Z", "dims=(x, y, z)"},
      {"--type T", "type=..."},
      {"--macet-relax", "macet_relax"},
      {"--dc-solver", "dc_solver"},
      {"--dc-hermite", "dc_hermite"},
      {"--dc-vertices", "dc_vertices"},
      {"--check-intersections", "check_intersections"},
      {"--quality", "quality"},
      {"--quads", "quads"},
      {"--backend", "backend"},
      {"--normals", "normals"},
      {"--frame", "frame"},
      {"--simplify", "simplify"},
      {"--memory", "memory"},
      {"--ascii", "ascii"},
      {"--stats", "stats"},
      {"--dims", "dims"},
      {"--type", "type"},
      {"--spacing", "spacing"},
      {"--origin", "origin"},
      {"--endian", "endian"},
      {"--series", "series"},
      {"--threads", "threads"},
      {"--method", "method"},
      {"--iso", "iso"},
  };
  return rename_options(std::move(message), kTerms);
}

PYBIND11_MODULE(_isotile, m) {
  m.doc() = "isotile's C++ libraries for NumPy arrays (use the isotile package, not this module)";
  m.attr("__version__") = std::string(isotile::version());
#ifdef ISOTILE_PYTHON_GL
  isotile::gl::register_gl_backends();
  // A GL context a run made is ended before the interpreter finishes, as the CLI ends its own
  // (gl::shutdown()): nothing is left to the drivers' exit handlers (docs/gl.md). Without the GIL,
  // which a run still going on another thread may need to end.
  py::module_::import("atexit").attr("register")(py::cpp_function([] {
    py::gil_scoped_release release;
    isotile::gl::shutdown();
  }));
#endif
  static py::exception<Cancelled> cancelled(m, "Cancelled", PyExc_Exception);
  // No face at the isovalue: a ValueError as extract's other bad inputs, and the RuntimeError
  // scikit-image's marching_cubes raises, so code written for either catches it.
  static PyObject* const no_surface = PyErr_NewException(
      "isotile.NoSurface",
      py::make_tuple(py::handle(PyExc_ValueError), py::handle(PyExc_RuntimeError)).release().ptr(),
      nullptr);
  m.attr("NoSurface") = py::handle(no_surface);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Cancelled& e) {
      PyErr_SetString(cancelled.ptr(), e.what());
    } catch (const NoSurfaceError& e) {
      PyErr_SetString(no_surface, in_python_terms(e.what()).c_str());
    } catch (const InputError& e) {
      PyErr_SetString(PyExc_ValueError, in_python_terms(e.what()).c_str());
    } catch (const IoError& e) {
      PyErr_SetString(PyExc_OSError, e.what());
    } catch (const CapacityError& e) {
      PyErr_SetString(PyExc_MemoryError, in_python_terms(e.what()).c_str());
    } catch (const Error& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
    }
  });
  m.def("extract", &extract_arrays, py::arg("volume"), py::arg("whole"), py::arg("level"),
        py::arg("spacing_xyz"), py::arg("method"), py::arg("quality"), py::arg("backend"),
        py::arg("normals"), py::arg("values"), py::arg("mask"), py::arg("threads"),
        "extract(view [z,y,x], level, spacing (x,y,z), ...) -> positions (x,y,z), faces (wound "
        "out of the samples >= level), normals, values; arrays own the library's buffers");
  m.def("quality", &quality_of, py::arg("vertices"), py::arg("faces"),
        py::arg("check_intersections"), py::arg("threads"));
  m.def("simplify", &simplify_arrays, py::arg("vertices"), py::arg("faces"), py::arg("ratio"),
        py::arg("faces_target"), py::arg("max_error"), py::arg("min_quality"), py::arg("relax"),
        py::arg("threads"));
  m.def("_time_library_calls", &time_library_calls, py::arg("volume"), py::arg("level"),
        py::arg("method"), py::arg("normals"), py::arg("threads"), py::arg("repeats"));
  py::class_<VolumeHandle, std::shared_ptr<VolumeHandle>>(m, "VolumeHandle")
      .def_property_readonly("samples", [](const py::object& self) { return samples_of(self); })
      .def_property_readonly("spacing", [](const VolumeHandle& h) { return h.volume.spacing(); })
      .def_property_readonly("origin", [](const VolumeHandle& h) { return h.volume.origin(); })
      .def_property_readonly("world_origin",
                             [](const VolumeHandle& h) {
                               return h.volume.world() ? h.volume.world()->origin
                                                       : h.volume.origin();
                             })
      .def_property_readonly("direction",
                             [](const VolumeHandle& h) {
                               const Mat3 d =
                                   h.volume.world() ? h.volume.world()->direction : kIdentity3;
                               return std::vector<std::vector<double>>{
                                   {d[0], d[1], d[2]}, {d[3], d[4], d[5]}, {d[6], d[7], d[8]}};
                             })
      .def_property_readonly("name", [](const VolumeHandle& h) { return h.name; });
  m.def("read_volume", &read_volume_py, py::arg("path"), py::arg("raw"));
  m.def("run_pipeline", &run_pipeline_py, py::arg("source"), py::arg("options"),
        py::arg("progress"), py::arg("threads"),
        "the library's pipeline (tiler/pipeline.h) -> (mesh arrays or None, stats JSON or None)");
  m.def("read_mesh", &read_mesh_py, py::arg("path"));
  m.def("write_mesh", &write_mesh_py, py::arg("vertices"), py::arg("faces"), py::arg("quads"),
        py::arg("normals"), py::arg("path"), py::arg("ascii"));
  m.def(
      "backends",
      [] {
        // Without the GIL: the GL backends' probe waits for the GL context's lock, which a run on
        // another thread holds while its progress callback, on the context's thread, waits for
        // the GIL.
        std::vector<BackendCaps> caps;
        {
          py::gil_scoped_release release;
          caps = capabilities();
        }
        py::dict d;
        for (const BackendCaps& c : caps)
          d[py::str(std::string(backend_name(c.backend)))] =
              c.available ? py::object(py::str("")) : py::object(py::str(c.why_unavailable));
        return d;
      },
      "{backend: '' when available, else why not}");
}
