#include "core/extract/extract.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <string>

#include "core/errors.h"
#include "core/extract/dual_contouring.h"
#include "core/extract/macet.h"
#include "core/extract/marching_cubes.h"

namespace isotile {

namespace {

Mesh cpu_marching_cubes(const VolumeView& view, const ExtractOptions& o, GpuReport*) {
  return marching_cubes(
      view, {.iso = o.iso, .normals = o.normals, .cells = o.cells, .progress = o.progress});
}

Mesh cpu_dual_contouring(const VolumeView& view, const ExtractOptions& o, GpuReport*) {
  return dual_contouring(view, dual_contouring_options(o));
}

Mesh cpu_macet(const VolumeView& view, const ExtractOptions& o, GpuReport*) {
  return macet(view, macet_options(o));
}

struct BackendEntry {
  Backend backend;
  std::string_view name;
  // Indexed by Method; nullptr where the backend does not implement the method.
  std::array<ExtractFn, kMethodCount> run;
  // Empty when the backend is compiled in; otherwise why it is not.
  std::string_view missing;
  // Set by register_backend(): whether it can run here (see extract.h).
  ProbeFn probe = nullptr;
  StartFn start = nullptr;  // start_backend()
  StartFailureFn start_failure = nullptr;
  PrepareFn prepare = nullptr;  // prepare_backend()
};

// The GL entries are filled by register_backend() (isotile_gl's register_gl_backends()); until
// then they say they are not built in, and selecting them is a clear error rather than a silent
// fallback.
std::array<BackendEntry, kBackendCount - 1> kBackends = {{
    {Backend::Cpu, "cpu", {cpu_marching_cubes, cpu_macet, cpu_dual_contouring}, ""},
    {Backend::GeometryShader,
     "gs",
     {nullptr, nullptr, nullptr},
     "the OpenGL geometry-shader backend is not built into this version"},
    {Backend::HistoPyramid,
     "hp",
     {nullptr, nullptr, nullptr},
     "the OpenGL HistoPyramid backend is not built into this version"},
}};
static_assert(kBackends.size() == kBackendCount - 1, "one table entry per concrete backend");

constexpr std::array<std::string_view, kMethodCount> kMethodNames = {"mc", "macet", "dc"};

const BackendEntry& entry(Backend b) {
  for (const auto& e : kBackends)
    if (e.backend == b) return e;
  throw InputError("unknown backend");
}

// The one form of a backend's own errors: "backend 'hp': why".
std::string backend_error(const BackendEntry& e, std::string_view why) {
  return "backend '" + std::string(e.name) + "': " + std::string(why);
}

// Auto's rules, the first whose backend implements the method and can run here wins. Measured on
// an NVIDIA H200 (docs/gl.md), the HistoPyramid path is 4-7x slower than the CPU at 16 threads
// and llvmpipe is slower still, so no rule sends a machine to a GL path yet; a measured rule
// (device, memory, upload rate) belongs here, above the CPU's.
struct AutoRule {
  Backend backend;
  std::string_view reason;
};
constexpr std::array<AutoRule, 1> kAutoRules = {{
    {Backend::Cpu,
     "auto: the CPU (no GL path has been measured faster than the CPU on any device yet)"},
}};

// Whether `e` can run here; `why` says why not, `hardware` whether it runs on a real GPU.
// `hardware_only`: only a real GPU matters (Auto), which the probe may rule out cheaply.
bool usable(const BackendEntry& e, std::string* why, bool* hardware, bool hardware_only = false) {
  *hardware = false;
  if (!e.missing.empty()) {
    *why = e.missing;
    return false;
  }
  *why = e.probe ? e.probe(hardware, hardware_only) : "";
  return why->empty();
}

}  // namespace

DualContouringOptions dual_contouring_options(const ExtractOptions& o) {
  DualContouringOptions dc;
  dc.iso = o.iso;
  dc.solver = o.dc_solver;
  dc.keep_quads = o.keep_quads;
  dc.normals = o.normals;
  dc.hermite = o.dc_hermite;
  dc.vertices = o.dc_vertices;
  dc.cells = o.cells;
  dc.progress = o.progress;
  return dc;
}

MacetOptions macet_options(const ExtractOptions& o) {
  MacetOptions m;
  m.iso = o.iso;
  m.normals = o.normals;
  m.quality = o.quality;
  m.relax = o.macet_relax;
  m.cells = o.cells;
  m.progress = o.progress;
  return m;
}

void check_method_options(const ExtractOptions& o) {
  if (!(o.macet_relax >= 0 && o.macet_relax < 0.5))
    throw InputError("macet_relax must be in [0, 0.5), got " + number_text(o.macet_relax));
  const ExtractOptions d;
  const std::pair<bool, std::string_view> set[] = {
      {o.macet_relax != d.macet_relax, "--macet-relax"},
      {o.quality != d.quality, "--quality"},
      {o.keep_quads != d.keep_quads, "--quads"},
      {o.dc_solver != d.dc_solver, "--dc-solver"},
      {o.dc_hermite != d.dc_hermite, "--dc-hermite"},
      {o.dc_vertices != d.dc_vertices, "--dc-vertices"},
  };
  for (const auto& [away, option] : set)
    if (away) check_option_method(option, o.method);
}

void check_option_method(std::string_view option, Method method) {
  const Method owner =
      option == "--quads" || option.starts_with("--dc-") ? Method::DualContouring : Method::Macet;
  if (method != owner)
    throw InputError(std::string(option) + " applies to --method " +
                     std::string(method_name(owner)) + " only");
}

std::string_view method_name(Method m) {
  const int i = static_cast<int>(m);
  if (i < 0 || i >= kMethodCount) throw InputError("unknown method " + std::to_string(i));
  return kMethodNames[i];
}

void check_extraction_input(const VolumeView& view, double iso) {
  if (!std::isfinite(iso))
    throw InputError("--iso must be a finite number, got " + number_text(iso));
  scalar_size(view.type);  // throws for a type outside the enum
  for (int a = 0; a < 3; ++a)
    if (view.dims[a] < 0 || view.global_dims[a] < 0)
      throw InputError("a volume view's dims must not be negative");
  if (view.sample_count() > 0 && view.data == nullptr)
    throw InputError("a volume view of " + std::to_string(view.sample_count()) +
                     " samples without data (a null pointer)");
  const Index3 dims = view.global_dims[0] > 0 ? view.global_dims : view.dims;
  check_grid_geometry(dims, view.spacing, view.origin, view.world, "the volume");
}

std::string_view backend_name(Backend b) {
  if (b == Backend::Auto) return "auto";
  return entry(b).name;
}

void register_backend(Backend backend, const std::array<ExtractFn, kMethodCount>& run,
                      ProbeFn probe, StartFn start, StartFailureFn start_failure,
                      PrepareFn prepare) {
  for (auto& e : kBackends)
    if (e.backend == backend) {
      e.run = run;
      e.missing = "";
      e.probe = probe;
      e.start = start;
      e.start_failure = start_failure;
      e.prepare = prepare;
    }
}

void prepare_backend(const ExtractOptions& options, ScalarType type, std::uint64_t sample_bytes) {
  if (options.backend == Backend::Auto) return;
  if (const auto& e = entry(options.backend); e.prepare) e.prepare(options, type, sample_bytes);
}

void start_backend(Backend backend) {
  if (backend == Backend::Auto) return;
  if (const auto& e = entry(backend); e.start) e.start();
}

std::string backend_start_failure(Backend backend) {
  if (backend == Backend::Auto) return {};
  const auto& e = entry(backend);
  if (!e.start_failure) return {};
  const std::string why = e.start_failure();
  return why.empty() ? why : backend_error(e, why);
}

std::vector<BackendCaps> capabilities() {
  std::vector<BackendCaps> caps;
  for (const auto& e : kBackends) {
    std::string why;
    bool hardware = false;
    const bool ok = usable(e, &why, &hardware);
    BackendCaps c{e.backend, ok, hardware, {}, why};
    for (int m = 0; m < kMethodCount; ++m)
      if (e.run[m]) c.methods.push_back(static_cast<Method>(m));
    caps.push_back(std::move(c));
  }
  return caps;
}

BackendChoice choose_backend(const ExtractOptions& options) {
  const int m = static_cast<int>(options.method);
  if (options.backend != Backend::Auto) return {resolve_backend(options), "requested"};
  if (const char* env = std::getenv("ISOTILE_AUTO_BACKEND"); env && *env) {
    const std::string want = env;
    for (const auto& e : kBackends) {
      if (e.name != want) continue;
      std::string why;
      bool hardware = false;
      if (e.run[m] && usable(e, &why, &hardware))
        return {e.backend, "auto: ISOTILE_AUTO_BACKEND=" + want};
      return {Backend::Cpu, "auto: the CPU (ISOTILE_AUTO_BACKEND=" + want + " cannot run " +
                                std::string(method_name(options.method)) + " here" +
                                (why.empty() ? "" : ": " + why) + ")"};
    }
    throw InputError("ISOTILE_AUTO_BACKEND='" + want + "' names no backend (cpu, gs, hp)");
  }
  for (const AutoRule& rule : kAutoRules) {
    const auto& e = entry(rule.backend);
    std::string why;
    bool hardware = false;
    if (e.run[m] && usable(e, &why, &hardware)) return {rule.backend, std::string(rule.reason)};
  }
  throw InputError("method '" + std::string(method_name(options.method)) +
                   "' is not implemented by any backend of this build");
}

Backend resolve_backend(const ExtractOptions& options) {
  const int m = static_cast<int>(options.method);
  if (options.backend == Backend::Auto) return choose_backend(options).backend;
  const auto& e = entry(options.backend);
  if (!e.run[m] && !e.missing.empty()) throw InputError(backend_error(e, e.missing));
  if (!e.run[m])
    throw InputError("backend '" + std::string(e.name) + "' does not implement method '" +
                     std::string(method_name(options.method)) + "'");
  std::string why;
  bool hardware = false;
  if (!usable(e, &why, &hardware)) throw InputError(backend_error(e, why));
  return options.backend;
}

TopologyOptions volume_border(const VolumeView& view, Method method) {
  std::array<Vec3f, 2> box{}, inner{};
  const double depth = method == Method::DualContouring ? 1.0 : 0.0;
  for (int a = 0; a < 3; ++a) {
    const double last = static_cast<double>(view.global_dims[a] - 1);
    box[0][a] = static_cast<float>(view.origin[a] + view.spacing[a] * 0.0);
    box[1][a] = static_cast<float>(view.origin[a] + view.spacing[a] * last);
    inner[0][a] = static_cast<float>(view.origin[a] + view.spacing[a] * std::min(depth, last));
    inner[1][a] =
        static_cast<float>(view.origin[a] + view.spacing[a] * std::max(last - depth, 0.0));
  }
  return {.border_box = box, .border_inner = inner};
}

int extract_halo(const ExtractOptions& options) {
  switch (options.method) {
    case Method::MarchingCubes:
      return marching_cubes_halo({.iso = options.iso, .normals = options.normals});
    case Method::Macet:
      return macet_halo({.iso = options.iso,
                         .normals = options.normals,
                         .quality = options.quality,
                         .relax = options.macet_relax});
    case Method::DualContouring:
      return dual_contouring_halo(dual_contouring_options(options));
  }
  return 2;
}

void accumulate_gpu_report(std::optional<GpuReport>& total, const GpuReport& part) {
  if (!total) {
    total = part;
    return;
  }
  for (const auto& [stage, seconds] : part.seconds) {
    auto it = std::find_if(total->seconds.begin(), total->seconds.end(),
                           [&](const auto& s) { return s.first == stage; });
    if (it == total->seconds.end())
      total->seconds.emplace_back(stage, seconds);
    else
      it->second += seconds;
  }
  total->upload_bytes += part.upload_bytes;
  total->upload_seconds += part.upload_seconds;
  total->context_seconds = std::max(total->context_seconds, part.context_seconds);
  total->programs_loaded += part.programs_loaded;
  total->programs_compiled += part.programs_compiled;
  total->programs_rejected += part.programs_rejected;
  if (total->program_cache_off.empty()) total->program_cache_off = part.program_cache_off;
}

Mesh extract(const VolumeView& view, const ExtractOptions& options, BackendChoice* ran) {
  check_extraction_input(view, options.iso);
  method_name(options.method);  // throws for a method outside the enum
  const int m = static_cast<int>(options.method);
  BackendChoice choice = choose_backend(options);
  const Backend b = choice.backend;
  auto run = [&] {
    GpuReport report;
    GpuReport* const wanted = ran && b != Backend::Cpu ? &report : nullptr;
    Mesh mesh = entry(b).run[m](view, options, wanted);
    if (wanted) choice.gpu = std::move(report);
    if (ran) *ran = std::move(choice);
    return mesh;
  };
  if (options.backend != Backend::Auto || b == Backend::Cpu) return run();
  try {
    return run();
  } catch (const Error& e) {
    say_warning(options.warn, "the " + std::string(entry(b).name) + " backend failed (" + e.what() +
                                  "); extracting on the CPU instead");
    if (ran)
      *ran = {Backend::Cpu, "auto: the CPU after the " + std::string(entry(b).name) +
                                " backend failed: " + e.what()};
    return entry(Backend::Cpu).run[m](view, options, nullptr);
  }
}

}  // namespace isotile
