// The one entry point: extract(view, options) runs the chosen method on the chosen backend.
//
// Backends are described by one table (extract.cpp) indexed by Backend, checked against the
// enum's size at compile time; capabilities() reports what this build and machine can run.
// Backend::Auto resolves by one table of rules (extract.cpp, docs/gl.md); the CPU is the
// reference and the fallback. Until a GL path is measured faster than the CPU on some device,
// the table sends every machine to the CPU; the GL paths stay one option away.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/extract/dual_contouring.h"
#include "core/extract/macet.h"
#include "core/mesh/mesh.h"
#include "core/mesh/mesh_topology.h"
#include "core/progress.h"
#include "core/volume/volume.h"

namespace isotile {

enum class Method { MarchingCubes, Macet, DualContouring };
inline constexpr int kMethodCount = 3;
enum class Backend { Cpu, GeometryShader, HistoPyramid, Auto };
inline constexpr int kBackendCount = 4;

std::string_view method_name(Method m);    // "mc", "macet", "dc"
std::string_view backend_name(Backend b);  // "cpu", "gs", "hp", "auto"

struct ExtractOptions {
  Method method = Method::MarchingCubes;
  Backend backend = Backend::Auto;
  double iso = 0.0;
  bool normals = false;
  // Dual Contouring only.
  DcSolver dc_solver = DcSolver::MassPoint;
  bool keep_quads = false;
  DcHermite dc_hermite = DcHermite::Central;   // Eno: sharper features, see dual_contouring.h
  DcVertices dc_vertices = DcVertices::Patch;  // Cell: the paper's one vertex per cell
  // Macet only: Fast (default) or Max (see core/extract/macet.h).
  MacetQuality quality = MacetQuality::Fast;
  double macet_relax = 0.0;  // MacetOptions::relax: 0 keeps vertices on the trilinear surface
  // Brick mode (global cell indices; empty: every cell of the view): the tiler extracts one
  // brick at a time from a view holding it plus extract_halo() samples. The brick contract is
  // set out in the source tree's core/extract/marching_cubes.h and core/extract/brick_sites.h
  // (not installed: the extractors' internals).
  Box3 cells{};
  // Told of the extraction's progress (Stage::Count, Stage::Extract, Stage::MacetSearch); null:
  // nobody listens. Cancelling throws Cancelled.
  Progress* progress = nullptr;
  // Told when Backend::Auto's GPU backend fails and the CPU extracts instead (core/progress.h);
  // null: stderr.
  Warn warn{};
};

// InputError when macet_relax is out of [0, 0.5), or a method's own options are set away from
// their defaults with another method (they would be dropped without a word). Messages name the
// CLI's options, which front ends may rename.
void check_method_options(const ExtractOptions& options);

// InputError "OPTION applies to --method M only" when the method-specific CLI option `option`
// (--quality, --macet-relax: Macet; --quads, --dc-*: Dual Contouring) is not `method`'s: the
// rule check_method_options() applies to values, for a front end that refuses such an option
// whenever it is given.
void check_option_method(std::string_view option, Method method);

// InputError unless `view` and `iso` can make a mesh: iso finite; a scalar type of the enum; dims
// not negative; data where there are samples; the grid's geometry (check_grid_geometry: spacing
// finite and positive, origin and world frame finite, positions within float32). extract(),
// macet() and dual_contouring() check it first: a zero or negative spacing made a flat or
// inside-out mesh, a NaN one NaN vertices, a NaN isovalue an empty mesh, all without a word. The
// samples themselves are not read twice: NaN or Inf samples are check_finite()'s to refuse
// (core/volume/volume_io.h; the pipeline calls it), and make NaN vertices here.
void check_extraction_input(const VolumeView& view, double iso);

// Samples beyond a brick's cells that `options` needs the view to hold.
int extract_halo(const ExtractOptions& options);

// The method's own options from `options` (the CPU and the GL backends run them alike).
DualContouringOptions dual_contouring_options(const ExtractOptions& options);
MacetOptions macet_options(const ExtractOptions& options);

// The border of the whole volume of `view` for mesh_topology(), so that `watertight` means the
// same for every method: closed except where the surface leaves the volume. The box is computed
// as extractors compute positions (vertices on the border compare equal to it); Dual
// Contouring's vertices there lie in the border cells, so its border layer is one voxel deep.
TopologyOptions volume_border(const VolumeView& view, Method method);

struct BackendCaps {
  Backend backend;
  bool available = false;
  bool hardware = false;        // runs on a real GPU (not the CPU, not a software rasteriser)
  std::vector<Method> methods;  // methods this backend implements
  std::string why_unavailable;  // empty when available
};

// One entry per concrete backend (Auto excluded), in enum order.
std::vector<BackendCaps> capabilities();

// The concrete backend `options` would run on; throws InputError (naming what is missing) when the
// requested backend or method is not available.
Backend resolve_backend(const ExtractOptions& options);

// resolve_backend() with the reason: "requested" for an explicit backend, else the Auto rule
// that chose it. ISOTILE_AUTO_BACKEND=cpu|gs|hp overrides the rules (diagnosis and tests); an
// override whose backend cannot run here gives the CPU, saying why.
// What a GL backend reports about one extraction: plain data, so that core does not depend on GL
// (the GL backends fill it; `isotile extract --stats` writes it, docs/cli.md).
struct GpuReport {
  // Seconds per stage, summed over the slabs, in the driver's order ("upload", "prepare",
  // "classify", "scan", "vertices", "faces", "readback"), from GL timer queries; then
  // "programs", the wall seconds spent making the run's programs (loaded or compiled), and
  // "pinned", making the pinned staging and read-back buffers (once per process); both include
  // what prepare_backend() made for this run while its volume was read.
  std::vector<std::pair<std::string, double>> seconds;
  std::uint64_t upload_bytes = 0;  // bytes of samples uploaded, as stored
  double upload_seconds = 0;       // from the first byte handed to GL until resident, summed
  double context_seconds = 0;      // the process's GL context start-up (EGL or OSMesa, driver)
  // The on-disk program cache over this extraction (and its preparation): programs loaded from it,
  // compiled, and entries rejected (corrupt or stale); `program_cache_off` says why it was not
  // used ("" if used).
  int programs_loaded = 0, programs_compiled = 0, programs_rejected = 0;
  std::string program_cache_off;
};

// Adds one extraction's report into the report of a run made of several (the tiler's bricks):
// stage seconds by name, bytes, upload seconds and programs summed; the context start-up (one per
// process, the same in every part) and the cache's "off" reason taken once.
void accumulate_gpu_report(std::optional<GpuReport>& total, const GpuReport& part);

struct BackendChoice {
  BackendChoice() = default;
  BackendChoice(Backend b, std::string why) : backend(b), reason(std::move(why)) {}
  Backend backend = Backend::Cpu;
  std::string reason;
  std::optional<GpuReport> gpu;  // set by extract() when a GL backend made the mesh
};
BackendChoice choose_backend(const ExtractOptions& options);

// Under Backend::Auto, a GL backend that fails (any isotile::Error) is followed by the CPU, with
// one line naming the failure to options.warn (null: stderr): Auto never fails where the CPU
// would succeed. `ran`, when
// given, gets the backend that made the mesh and why.
Mesh extract(const VolumeView& view, const ExtractOptions& options, BackendChoice* ran = nullptr);

// Optional backends live in their own targets (the GL ones in shaders/, isotile_gl) so that core
// does not depend on them; the program installs them at startup, before any extract(). `probe`
// returns "" when the backend can run on this machine, setting *hardware when it runs on a real
// GPU (Auto picks a GPU backend only then), else why it cannot; with `hardware_only` (Auto's
// question) it may answer "cannot" cheaply for anything but a real GPU.
// `report`, when not null, gets the backend's account (GL backends only; the CPU leaves it).
// `start`, when not null, begins in the background what the backend needs before its first
// extract() and takes long (start_backend()).
using ExtractFn = Mesh (*)(const VolumeView&, const ExtractOptions&, GpuReport* report);
using ProbeFn = std::string (*)(bool* hardware, bool hardware_only);
// `start_failure`, given with `start`, says without waiting why that work failed, once it has
// ("" while it runs, succeeded or was not started).
using StartFn = void (*)();
using StartFailureFn = std::string (*)();
// `prepare`, given with `start`, begins in the background what the backend's first extract() with
// these options on samples of this type and byte size does first and takes long
// (prepare_backend()).
using PrepareFn = void (*)(const ExtractOptions& options, ScalarType type,
                           std::uint64_t sample_bytes);
void register_backend(Backend backend, const std::array<ExtractFn, kMethodCount>& run,
                      ProbeFn probe, StartFn start = nullptr,
                      StartFailureFn start_failure = nullptr, PrepareFn prepare = nullptr);

// For a backend asked for by name (not Auto, which must probe first): starts in the background
// what it needs before its first extract() and takes long, so that it overlaps the caller's
// reading of the volume (the GL backends: their context, tenths of a second on a GPU). Then the
// backend's probe answers without waiting: it can run unless that work has failed already; if it
// fails, every extract() on it throws the InputError the probe would have, and
// backend_start_failure() says so at once. Not for Auto, the CPU, backends without such work.
void start_backend(Backend backend);

// After start_backend(options.backend), once the samples' type and byte size are known and before
// they are read: begins on the backend's own thread what its first extract() with `options` on
// such samples does first and takes long (the GL backends: loading or compiling the method's
// programs for that sample type, making the pinned staging buffers for that many bytes), so that
// it too overlaps the read. Never waits and never throws: what fails there fails again in the
// extraction, which reports it. The extraction's report (GpuReport) counts the programs and
// buffers so made as its own. Not for Auto, the CPU, backends without such work.
void prepare_backend(const ExtractOptions& options, ScalarType type, std::uint64_t sample_bytes);

// Without waiting: the error every extract() on `backend` will throw because what
// start_backend() began for it has failed ("backend 'hp': no usable OpenGL 4.5 context (...)"),
// or "" (not failed, not started, or nothing to start). The pipeline asks it while it reads the
// volume, so that a run whose context failed ends then and not after the read.
std::string backend_start_failure(Backend backend);

}  // namespace isotile
