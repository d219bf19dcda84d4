// Brick planning for the GL extractors and their installation into core's backend table.
#include "gl_backends.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "dc_gl.h"
#include "gl_context.h"
#include "gl_program.h"
#include "macet_gl.h"
#include "program_cache.h"
#include "sample_upload.h"
#include "stage_clock.h"

namespace isotile::gl {

std::uint64_t memory_budget(std::uint64_t requested) {
  if (requested > 0) return requested;
  const DeviceInfo& dev = device();
  if (dev.memory_free_kib > 0) return static_cast<std::uint64_t>(dev.memory_free_kib) * 1024 / 2;
  return std::uint64_t{1} << 30;
}

Box3 cells_to_extract(const VolumeView& view, const Box3& cells) {
  Box3 all;
  for (int a = 0; a < 3; ++a) {
    all.lo[a] = view.box.lo[a];
    all.hi[a] = view.box.hi[a] - 1;
  }
  if (cells.empty()) return all;
  Box3 b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = std::max(cells.lo[a], all.lo[a]);
    b.hi[a] = std::min(cells.hi[a], all.hi[a]);
  }
  return b;
}

Box3 slab_region(const VolumeView& view, const Box3& cells, int halo) {
  Box3 r;
  for (int a = 0; a < 3; ++a) {
    // Cells need samples [lo, hi]; the closed box's edges reach hi + 1; gradients one more.
    r.lo[a] = std::max(cells.lo[a] - halo, view.box.lo[a]);
    r.hi[a] = std::min(cells.hi[a] + 2 + halo, view.box.hi[a]);
  }
  return r;
}

std::vector<Box3> plan_slabs(const VolumeView& view, const Box3& cells, double bytes_per_sample,
                             double largest_per_sample, int halo, std::uint64_t budget,
                             std::int64_t max_cells_z) {
  std::vector<Box3> slabs;
  if (cells.empty()) return slabs;
  const DeviceInfo& dev = device();
  // The largest storage-buffer binding, and never more than 2 GiB (32-bit element indices).
  const double binding =
      static_cast<double>(std::min<std::int64_t>(dev.max_ssbo_bytes, std::int64_t{1} << 31));
  const Box3 full = slab_region(view, cells, halo);
  const double plane = static_cast<double>(full.extent(0) * full.extent(1));
  const double planes = std::min(static_cast<double>(budget) / (plane * bytes_per_sample),
                                 binding / (plane * largest_per_sample));
  // A slab of t cells uploads t + 2 + 2 * halo sample planes, fewer where the volume's faces clip
  // its halo: when the whole z range fits, one slab takes it, however wide the halo (Macet max's
  // is tens of samples).
  std::int64_t t = static_cast<std::int64_t>(std::floor(planes)) - 2 - 2 * halo;
  if (static_cast<double>(full.extent(2)) <= std::floor(planes)) t = std::max(t, cells.extent(2));
  if (t < 1)
    throw CapacityError("one x-y slab of " + std::to_string(full.extent(0)) + " x " +
                        std::to_string(full.extent(1)) +
                        " samples does not fit the GL device's buffers (bricking in x and y is "
                        "not implemented for the GL backends; use the CPU backend)");
  if (max_cells_z > 0) t = std::min(t, max_cells_z);
  for (std::int64_t z = cells.lo[2]; z < cells.hi[2]; z += t) {
    Box3 s = cells;
    s.lo[2] = z;
    s.hi[2] = std::min(z + t, cells.hi[2]);
    slabs.push_back(s);
  }
  return slabs;
}

std::vector<Box3> plan_overlapped_slabs(const VolumeView& view, const Box3& cells,
                                        double sample_bytes, double method_bytes,
                                        double largest_per_sample, int halo, std::uint64_t budget,
                                        std::int64_t max_cells_z) {
  const double largest = std::max(sample_bytes, largest_per_sample);
  std::vector<Box3> slabs =
      plan_slabs(view, cells, sample_bytes + method_bytes, largest, halo, budget, max_cells_z);
  if (slabs.size() > 1)
    slabs = plan_slabs(view, cells, 2 * sample_bytes + method_bytes, largest, halo, budget,
                       max_cells_z);
  return slabs;
}

namespace {

McOptions mc_options(const ExtractOptions& o) {
  McOptions m;
  m.iso = o.iso;
  m.normals = o.normals;
  m.cells = o.cells;
  m.progress = o.progress;
  return m;
}

DcGlOptions dc_gl_options(const ExtractOptions& o) {
  DcGlOptions d;
  d.dc = dual_contouring_options(o);
  return d;
}

MacetGlOptions macet_gl_options(const ExtractOptions& o) {
  MacetGlOptions m;
  m.macet = macet_options(o);
  return m;
}

// What making programs (loaded or compiled) and pinned buffers has cost: the process's totals
// (now()), or what a span of it made (the difference of two).
struct Made {
  ProgramCacheCounts programs;
  double pinned_seconds = 0;

  static Made now() { return {program_cache_counts(), mapped_buffer_seconds()}; }
  Made& operator+=(const Made& o) { return add(o, 1); }
  Made operator-(const Made& o) const {
    Made d = *this;
    return d.add(o, -1);
  }

 private:
  Made& add(const Made& o, int sign) {
    programs.loaded += sign * o.programs.loaded;
    programs.compiled += sign * o.programs.compiled;
    programs.rejected += sign * o.programs.rejected;
    programs.seconds += sign * o.programs.seconds;
    pinned_seconds += sign * o.pinned_seconds;
    return *this;
  }
};
// What prepare()'s jobs made ahead of the next extraction, which that extraction's report counts
// as its own. On the context's thread only.
Made g_prepared;

// Runs `run` (a GL extractor taking McStats*) and, when `report` is given, fills it: the stages'
// device times, the upload, the program cache over this call and what prepare() made for it, the
// context's start-up.
template <class Run>
Mesh reported(const char* backend, GpuReport* report, Run run) {
  // The context that start_context() was making when the probe said yes may have failed: the
  // error the probe would have given (resolve_backend()).
  if (std::string why; !available(&why))
    throw InputError("backend '" + std::string(backend) + "': " + why);
  // The run and its report in one job on the context's thread, where the program cache's counts
  // before and after it are this run's alone.
  return on_context_thread([&] {
    const Made prepared = std::exchange(g_prepared, {});
    if (!report) return run(nullptr);
    const Made before = Made::now();
    McStats stats;
    Mesh mesh = run(&stats);
    Made made = Made::now() - before;
    made += prepared;
    report->seconds.clear();
    for (int s = 0; s < kGlStageCount; ++s)
      report->seconds.emplace_back(gl_stage_name(static_cast<GlStage>(s)), stats.times.seconds[s]);
    report->upload_bytes = stats.times.upload_bytes;
    report->upload_seconds = stats.times[GlStage::Upload];
    report->context_seconds = device().startup_seconds;
    report->programs_loaded = made.programs.loaded;
    report->programs_compiled = made.programs.compiled;
    report->programs_rejected = made.programs.rejected;
    report->seconds.emplace_back("programs", made.programs.seconds);
    report->seconds.emplace_back("pinned", made.pinned_seconds);
    std::string why;
    report->program_cache_off = program_cache_enabled(&why) ? "" : why;
    return mesh;
  });
}

Mesh run_gs(const VolumeView& view, const ExtractOptions& o, GpuReport* r) {
  return reported("gs", r, [&](McStats* s) { return mc_geometry_shader(view, mc_options(o), s); });
}

Mesh run_hp(const VolumeView& view, const ExtractOptions& o, GpuReport* r) {
  return reported("hp", r, [&](McStats* s) { return mc_histopyramid(view, mc_options(o), s); });
}

Mesh run_dc_gs(const VolumeView& view, const ExtractOptions& o, GpuReport* r) {
  return reported("gs", r,
                  [&](McStats* s) { return dc_geometry_shader(view, dc_gl_options(o), s); });
}

Mesh run_dc_hp(const VolumeView& view, const ExtractOptions& o, GpuReport* r) {
  return reported("hp", r, [&](McStats* s) { return dc_histopyramid(view, dc_gl_options(o), s); });
}

Mesh run_gs_macet(const VolumeView& view, const ExtractOptions& o, GpuReport* r) {
  return reported("gs", r,
                  [&](McStats* s) { return macet_geometry_shader(view, macet_gl_options(o), s); });
}

Mesh run_hp_macet(const VolumeView& view, const ExtractOptions& o, GpuReport* r) {
  return reported("hp", r,
                  [&](McStats* s) { return macet_histopyramid(view, macet_gl_options(o), s); });
}

// prepare_backend() for a GL backend whose extractors are `runs`: on the context's thread while
// the caller reads its volume, the pinned staging buffers for `sample_bytes`, then the method's
// programs for samples of `type`, by the same extractor on a volume of 4^3 such samples with a
// cube of 2^3 inside (every pass runs, so each loads its program; the isovalue is a uniform, not
// part of a program). A volume that needs several slabs also needs one more program (hp_prefix)
// and larger read-back buffers, both left to the extraction.
void prepare(const std::array<ExtractFn, kMethodCount>& runs, const ExtractOptions& options,
             ScalarType type, std::uint64_t sample_bytes) {
  ExtractOptions o = options;
  o.iso = 0.5;
  o.cells = {};
  o.progress = nullptr;
  o.warn = {};
  const ExtractFn run = runs[static_cast<std::size_t>(options.method)];
  start_on_context_thread([o, run, type, sample_bytes] {
    // The extractor below passes through reported(), which takes the account for its run: kept
    // aside, for the extraction this prepares.
    Made account = std::exchange(g_prepared, {});
    const Made before = Made::now();
    reserve_staging(static_cast<std::size_t>(sample_bytes));
    Volume v(type, {4, 4, 4});
    visit_scalar(type, [&](auto zero) {
      using T = decltype(zero);
      T* samples = v.data<T>();
      std::fill(samples, samples + v.sample_count(), zero);
      for (int z = 1; z < 3; ++z)
        for (int y = 1; y < 3; ++y)
          for (int x = 1; x < 3; ++x) samples[(z * 4 + y) * 4 + x] = T(1);
    });
    try {
      run(v.view(), o, nullptr);
    } catch (...) {
      // What fails here fails again in the extraction, which reports it.
    }
    account += Made::now() - before;
    g_prepared = account;
  });
}

constexpr std::array<ExtractFn, kMethodCount> kGsRuns = {run_gs, run_gs_macet, run_dc_gs};
constexpr std::array<ExtractFn, kMethodCount> kHpRuns = {run_hp, run_hp_macet, run_dc_hp};

void prepare_gs(const ExtractOptions& o, ScalarType type, std::uint64_t bytes) {
  prepare(kGsRuns, o, type, bytes);
}

void prepare_hp(const ExtractOptions& o, ScalarType type, std::uint64_t bytes) {
  prepare(kHpRuns, o, type, bytes);
}

// Usable when a context exists; "hardware" unless it is a software rasteriser, so that `auto`
// only prefers the GPU paths on a real GPU. For `auto` (hardware_only) a machine without a GPU is
// told apart without making a context (starting llvmpipe costs about 0.3 s).
std::string probe(bool* hardware, bool hardware_only) {
  if (hardware_only && !hardware_device_present()) return "no GPU (hardware EGL device) found";
  // Asked for by name once start_context() began making the context (start_backend()): yes
  // without waiting for it, so that the caller reads its volume meanwhile, unless it has failed
  // already; a later failure comes from backend_start_failure() during the read, or reported().
  if (!hardware_only && context_started()) return start_failure();
  std::string why;
  if (!available(&why)) return why;
  *hardware = !device().software;
  return {};
}

}  // namespace

ProgramCacheState program_cache_state() {
  device();  // the driver's binary formats decide
  ProgramCacheState s;
  s.folder = program_cache_dir().string();
  s.enabled = program_cache_enabled(&s.off_because);
  return s;
}

void register_gl_backends() {
  register_backend(Backend::GeometryShader, kGsRuns, probe, start_context, start_failure,
                   prepare_gs);
  register_backend(Backend::HistoPyramid, kHpRuns, probe, start_context, start_failure, prepare_hp);
}

}  // namespace isotile::gl
