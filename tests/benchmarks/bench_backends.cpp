// Marching Cubes, Macet (Fast) and Dual Contouring on the three backends (CPU, GL geometry shader,
// GL HistoPyramid), side by side in one run on the same in-memory volumes, after checking that all
// three give the same mesh.
//
//   cmake -S . -B build-bench -DISOTILE_BUILD_BENCHMARKS=ON
//   cmake --build build-bench --target bench_backends
//   build-bench/tests/benchmarks/bench_backends [--threads N] [--repeat R] [--methods mc,macet,dc]
//       [--data DIR] [--gyroid512] [--hold-context]
//
// Dual Contouring runs with the CLI's defaults (patch vertices, mass point, central Hermite data)
// and, as a second row per volume, the paper's particle minimizer (10 steps).
//
// Times are wall-clock medians of R runs (default 5) of the whole extraction call as a user sees
// it: upload, passes, read-back, (GS) weld. Each GL path runs once before timing, so shader
// compilation is not counted. --threads sets TBB's and llvmpipe's threads (LP_NUM_THREADS, read
// at context creation). The real volumes (engine, bonsai) are read from --data DIR, else from
// $ISOTILE_GPU_DATA (a GPU machine does not see ../shared), else from ../shared/data; each is
// skipped, with a message, when absent. --gyroid512 adds gyroid 512^3 float32 (512 MiB of samples;
// minutes on llvmpipe). "hpe" is the HistoPyramid with its per-element output passes
// (shaders/hp_pyramid.h's HpOutput::Scatter, ISOTILE_HP_OUTPUT=scatter) instead of the descents,
// timed in the same run. For Marching Cubes and Macet a second table gives, per volume, the GL
// stages of one more run of each path from GL timer queries (shaders/stage_clock.h), the upload's
// GB/s (bytes of samples / seconds from the first byte handed to GL until resident) and
// triangles/s of the median whole-call times. Before the volumes, a table of the read-back's
// GB/s on its own (device buffers of 16, 64 and 256 MiB; shaders/read_back.h) and one of the
// upload's (16, 64 and 256 MiB of samples, staging pieces of 2, 8 and 32 MiB, each submitted to
// the device as it is filled or not; shaders/sample_upload.h); `--methods none` prints only these
// two. With Marching Cubes, a table of whole HistoPyramid calls with the commands submitted early
// (gl::submit(), the default) and not follows them. Before it, what taking and releasing the
// context costs per call (bench_context_cycles()). --hold-context keeps the context current on the
// main thread for the whole run (one gl::Scope around it, borrowing it from the context's thread),
// so that the extractions run in place there instead of on the context's thread (gl_context.h): run
// with and without it, the difference is what handing each call to that thread costs.
#include <EGL/egl.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/extract/dual_contouring.h"
#include "core/extract/macet.h"
#include "core/extract/marching_cubes.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "shaders/dc_gl.h"
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#include "shaders/gl_program.h"
#include "shaders/hp_pyramid.h"
#include "shaders/macet_gl.h"
#include "shaders/read_back.h"
#include "shaders/sample_upload.h"

namespace {

using namespace isotile;

struct Case {
  std::string name;
  std::shared_ptr<Volume> volume;
  double iso;
};

double median(std::vector<double> t) {
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

double median_seconds(int repeat, const std::function<Mesh()>& run, Mesh& out) {
  std::vector<double> t;
  for (int r = 0; r < repeat; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    out = run();
    t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  return median(t);
}

bool same(const Mesh& a, const Mesh& b) {
  return a.positions == b.positions && a.triangles == b.triangles && a.normals == b.normals &&
         a.quads == b.quads;
}

// `run` with the HistoPyramid's per-element output passes instead of its descents.
template <class Run>
auto per_element(const Run& run) {
  gl::set_hp_output(gl::HpOutput::Scatter);
  auto result = run();
  gl::set_hp_output(std::nullopt);
  return result;
}

// Dual Contouring's rows: the CPU and both GL paths per volume and solver.
void bench_dual_contouring(const std::vector<Case>& cases, int repeat) {
  std::printf("\nDual Contouring (patch vertices, central Hermite data)\n");
  std::printf("%-12s %-9s %10s %10s %10s %10s %10s %8s %8s %8s  %s\n", "volume", "solver",
              "triangles", "cpu ms", "gs ms", "hp ms", "hpe ms", "gs/cpu", "hp/cpu", "hpe/cpu",
              "same mesh");
  for (const Case& c : cases)
    for (DcSolver solver : {DcSolver::MassPoint, DcSolver::Particle}) {
      const VolumeView v = c.volume->view();
      DualContouringOptions o;
      o.iso = c.iso;
      o.solver = solver;
      gl::DcGlOptions g;
      g.dc = o;
      Mesh cpu, gs, hp, hpe;
      const double t_cpu = median_seconds(
          repeat, [&] { return dual_contouring(v, o); }, cpu);
      gl::dc_geometry_shader(v, g);  // compile the shaders outside the timing
      const double t_gs = median_seconds(
          repeat, [&] { return gl::dc_geometry_shader(v, g); }, gs);
      gl::dc_histopyramid(v, g);
      const double t_hp = median_seconds(
          repeat, [&] { return gl::dc_histopyramid(v, g); }, hp);
      auto hp_per_element = [&] { return per_element([&] { return gl::dc_histopyramid(v, g); }); };
      hp_per_element();
      const double t_hpe = median_seconds(repeat, hp_per_element, hpe);
      std::printf("%-12s %-9s %10zu %10.1f %10.1f %10.1f %10.1f %8.1f %8.1f %8.1f  %s\n",
                  c.name.c_str(), solver == DcSolver::MassPoint ? "mass" : "particle",
                  cpu.triangles.size(), 1e3 * t_cpu, 1e3 * t_gs, 1e3 * t_hp, 1e3 * t_hpe,
                  t_gs / t_cpu, t_hp / t_cpu, t_hpe / t_cpu,
                  same(cpu, gs) && same(cpu, hp) && same(cpu, hpe) ? "yes" : "NO");
    }
}

// The way out by itself (shaders/read_back.h): a device buffer of the mesh arrays' size read into
// host memory already touched (as the mesh's arrays are), straight through
// glGetNamedBufferSubData and through the pinned buffers in pieces of a few sizes; best of
// `repeat` reads, each checked against the bytes put in.
void bench_read_back(int repeat) {
  const std::size_t pieces[] = {0, std::size_t{2} << 20, gl::kDefaultReadBackBytes,
                                std::size_t{32} << 20};
  std::printf(
      "\nread-back GB/s (best of %d): direct = glGetNamedBufferSubData into pageable "
      "memory, pinned N = %d persistently mapped buffers of N MiB\n",
      repeat, gl::kReadBackBuffers);
  std::printf("%-10s %10s", "MiB", "direct");
  for (std::size_t p : pieces)
    if (p) std::printf("   pinned %2zu", p >> 20);
  std::printf("  %s\n", "same bytes");
  gl::Scope scope;
  for (const std::size_t mib : {std::size_t{16}, std::size_t{64}, std::size_t{256}}) {
    const std::size_t bytes = mib << 20;
    std::vector<unsigned char> in(bytes), out(bytes, 0);
    for (std::size_t i = 0; i < bytes; ++i) in[i] = static_cast<unsigned char>(i * 131 + (i >> 20));
    const gl::Buffer device(bytes, in.data());
    bool all_same = true;
    std::printf("%-10zu", mib);
    for (const std::size_t piece : pieces) {
      gl::set_read_back_bytes(piece);
      double best = 1e30;
      for (int r = 0; r < repeat + 1; ++r) {  // the first read makes the pinned buffers
        std::fill(out.begin(), out.end(), 0);
        const auto t0 = std::chrono::steady_clock::now();
        device.read(0, bytes, out.data());
        const double t =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (r > 0) best = std::min(best, t);
        all_same = all_same && out == in;
      }
      std::printf(piece ? " %11.2f" : " %10.2f", static_cast<double>(bytes) / best / 1e9);
    }
    std::printf("  %s\n", all_same ? "yes" : "NO");
  }
  gl::use_default_read_back();
}

// The way in by itself (shaders/sample_upload.h): uint8 samples of 16, 64 and 256 MiB uploaded
// through the staging buffers in pieces of a few sizes, each piece handed to the device as it is
// filled (gl::submit()), and in the largest pieces without that (the copies then start at the
// next wait: the glFinish here); wall time until resident, best of `repeat`, each upload read back
// once and checked against the samples.
void bench_upload(int repeat) {
  const std::size_t pieces[] = {std::size_t{2} << 20, std::size_t{8} << 20,
                                gl::kDefaultStagingBytes};
  std::printf(
      "\nupload GB/s (best of %d): uint8 samples through %d pinned staging buffers of N MiB, each "
      "submitted as filled; unsubmitted = the copies left to the next wait\n",
      repeat, gl::kStagingBuffers);
  std::printf("%-10s", "MiB");
  for (std::size_t p : pieces) std::printf("  staging %2zu", p >> 20);
  std::printf("  %2zu unsubmitted  %s\n", gl::kDefaultStagingBytes >> 20, "same bytes");
  gl::Scope scope;
  for (const std::int64_t planes : {256, 1024, 4096}) {
    Volume v(ScalarType::UInt8, {256, 256, planes});
    auto* bytes = v.data<std::uint8_t>();
    const std::size_t n = static_cast<std::size_t>(v.sample_count());
    for (std::size_t i = 0; i < n; ++i) bytes[i] = static_cast<std::uint8_t>(i * 131 + (i >> 20));
    const Box3 all{{0, 0, 0}, {256, 256, planes}};
    bool all_same = true;
    std::printf("%-10zu", n >> 20);
    auto row = [&](std::size_t piece, bool submitted) {
      gl::set_staging_bytes(piece);
      gl::set_submit_early(submitted);
      double best = 1e30;
      for (int r = 0; r < repeat + 1; ++r) {  // the first upload makes the staging buffers
        const auto t0 = std::chrono::steady_clock::now();
        const gl::Samples samples = gl::upload_samples(v.view(), all);
        glFinish();
        const double t =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        if (r > 0) best = std::min(best, t);
        if (r == 0) {
          std::vector<std::uint8_t> back(n);
          samples.buffer.read(0, n, back.data());
          all_same = all_same && std::equal(back.begin(), back.end(), bytes);
        }
      }
      gl::set_submit_early(true);
      std::printf("  %10.2f", static_cast<double>(n) / best / 1e9);
    };
    for (std::size_t piece : pieces) row(piece, true);
    row(gl::kDefaultStagingBytes, false);
    std::printf("     %s\n", all_same ? "yes" : "NO");
  }
  gl::set_staging_bytes(gl::kDefaultStagingBytes);
}

// Whole HistoPyramid Marching Cubes calls with the commands handed to the device wherever the CPU
// goes on alone (gl::submit(): the default) and without (left to the next wait, as before), medians
// of `repeat` calls each, interleaved, the meshes compared.
void bench_submission(const std::vector<Case>& cases, int repeat) {
  std::printf("\nhp MC whole calls, ms: commands submitted early (default) and not\n");
  std::printf("%-12s %10s %12s %8s  %s\n", "volume", "submitted", "unsubmitted", "ratio",
              "same mesh");
  for (const Case& c : cases) {
    const VolumeView v = c.volume->view();
    auto call = [&] { return gl::mc_histopyramid(v, {.iso = c.iso}); };
    Mesh on = call(), off;
    std::vector<double> t_on, t_off;
    for (int r = 0; r < repeat; ++r)
      for (const bool early : {true, false}) {
        gl::set_submit_early(early);
        const auto t0 = std::chrono::steady_clock::now();
        (early ? on : off) = call();
        (early ? t_on : t_off)
            .push_back(
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      }
    gl::set_submit_early(true);
    const double a = median(t_on), b = median(t_off);
    std::printf("%-12s %10.1f %12.1f %8.2f  %s\n", c.name.c_str(), 1e3 * a, 1e3 * b, a / b,
                same(on, off) ? "yes" : "NO");
  }
}

// What taking the context on a thread and giving it back costs (gl_context.h's Scope: eglBindAPI
// and eglMakeCurrent; at the end of the thread's outermost Scope eglMakeCurrent with no context
// and eglReleaseThread), and which of those calls costs it: the same EGL calls by hand without
// eglReleaseThread and with it, a Scope taken while the context is current already; and a small
// extraction (HistoPyramid MC on sphere 32) as a call from this thread (run on the context's
// thread, which keeps the context), after a Scope on this thread each time (the context's thread
// takes it back: what every call paid before that thread existed), and inside a held Scope. Each
// bare cycle ends with a glFinish(), so that work a driver leaves to the first GL call after
// eglMakeCurrent is counted. Milliseconds per cycle, best of at most 3 rounds (a cycle took about
// 0.2 s on the H200), on this thread with no other Scope alive. OSMesa contexts: no rows by hand.
void bench_context_cycles(int repeat) {
  const int rounds = std::min(repeat, 3);
  auto per_cycle = [&](int cycles, const std::function<void()>& cycle) {
    double best = 1e30;
    for (int r = 0; r < rounds; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      for (int c = 0; c < cycles; ++c) cycle();
      best = std::min(best,
                      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    return 1e3 * best / cycles;
  };
  auto row = [](const char* what, double ms) { std::printf("%-66s %8.3f\n", what, ms); };
  auto bare_scope = [] {
    gl::Scope scope;
    glFinish();
  };
  const Volume sphere = make_field_volume({FieldKind::Sphere, 32});
  const double iso = field_default_iso(FieldKind::Sphere);
  auto small_extraction = [&] { gl::mc_histopyramid(sphere.view(), {.iso = iso}); };
  small_extraction();  // programs compiled or loaded outside the timing
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  {
    gl::Scope scope;
    display = eglGetCurrentDisplay();
    context = eglGetCurrentContext();
  }
  std::printf("\ncontext per take and release, ms (best of %d rounds)\n", rounds);
  row("gl::Scope, outermost on this thread", per_cycle(10, bare_scope));
  {
    gl::Scope outer;
    row("gl::Scope inside another (the context stays current)", per_cycle(10, bare_scope));
  }
  if (context != EGL_NO_CONTEXT) {
    auto by_hand = [&](bool release_thread) {
      return per_cycle(10, [&] {
        eglBindAPI(EGL_OPENGL_API);
        eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, context);
        glFinish();
        eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        if (release_thread) eglReleaseThread();
      });
    };
    row("eglMakeCurrent, eglMakeCurrent(no context)", by_hand(false));
    row("eglMakeCurrent, eglMakeCurrent(no context), eglReleaseThread", by_hand(true));
  }
  row("hp MC sphere 32, a call (on the context's thread)", per_cycle(5, small_extraction));
  row("hp MC sphere 32, each after a gl::Scope on this thread", per_cycle(5, [&] {
        bare_scope();
        small_extraction();
      }));
  {
    gl::Scope outer;
    row("hp MC sphere 32, inside a held gl::Scope", per_cycle(5, small_extraction));
  }
}

}  // namespace

int main(int argc, char** argv) {
  // Each row as it is measured, also into a pipe (tee): a run cut short keeps what it printed.
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  int threads = 2, repeat = 5;
  std::string methods = "mc,macet,dc";
  std::filesystem::path data = ISOTILE_SHARED_DATA;
  if (const char* env = std::getenv("ISOTILE_GPU_DATA"); env && *env) data = env;
  bool gyroid512 = false, hold_context = false;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      threads = std::atoi(argv[++i]);
    } else if (std::strcmp(argv[i], "--repeat") == 0 && i + 1 < argc) {
      repeat = std::atoi(argv[++i]);
    } else if (std::strcmp(argv[i], "--methods") == 0 && i + 1 < argc) {
      methods = argv[++i];
    } else if (std::strcmp(argv[i], "--data") == 0 && i + 1 < argc) {
      data = argv[++i];
    } else if (std::strcmp(argv[i], "--gyroid512") == 0) {
      gyroid512 = true;
    } else if (std::strcmp(argv[i], "--hold-context") == 0) {
      hold_context = true;
    } else {
      std::fprintf(stderr,
                   "bench_backends: unknown argument '%s' (--threads N, --repeat R, --methods "
                   "LIST, --data DIR, --gyroid512, --hold-context)\n",
                   argv[i]);
      return 2;
    }
  }
  if (threads < 1 || repeat < 1) {
    std::fprintf(stderr, "bench_backends: --threads and --repeat must be at least 1\n");
    return 2;
  }
  const bool run_mc = methods.find("mc") != std::string::npos;
  const bool run_macet = methods.find("macet") != std::string::npos;
  const bool run_dc = methods.find("dc") != std::string::npos;
  setenv("LP_NUM_THREADS", std::to_string(threads).c_str(), 1);
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  std::string why;
  if (!gl::available(&why)) {
    std::printf("no GL context: %s\n", why.c_str());
    return 1;
  }
  const gl::DeviceInfo& dev = gl::device();
  std::printf("device: %s (%s, %s), threads %d, median of %d runs%s\n", dev.renderer.c_str(),
              dev.platform.c_str(), dev.version.c_str(), threads, repeat,
              hold_context ? ", context held across the calls" : "");
  bench_context_cycles(repeat);
  std::optional<gl::Scope> hold;
  if (hold_context) hold.emplace();

  std::vector<Case> cases;
  std::vector<std::pair<FieldKind, int>> fields = {
      {FieldKind::Sphere, 128}, {FieldKind::Gyroid, 128}, {FieldKind::Gyroid, 256}};
  if (gyroid512) fields.emplace_back(FieldKind::Gyroid, 512);
  for (auto [kind, n] : fields) {
    const FieldSpec spec{kind, n};
    cases.push_back({std::string(field_name(kind)) + "-" + std::to_string(n),
                     std::make_shared<Volume>(make_field_volume(spec)), field_default_iso(kind)});
  }
  const std::filesystem::path& shared = data;
  std::printf("volumes from %s\n", data.c_str());
  for (auto [file, name] : {std::pair{"engine_256x256x128_uint8.raw.gz", "engine"},
                            std::pair{"bonsai_256x256x256_uint8.raw.gz", "bonsai"}}) {
    if (std::filesystem::exists(shared / file))
      cases.push_back(
          {name, std::make_shared<Volume>(read_volume((shared / file).string())), 49.5});
    else
      std::printf("skipping %s: %s not found\n", name, (shared / file).c_str());
  }

  bench_read_back(repeat);
  bench_upload(repeat);
  if (run_mc) bench_submission(cases, repeat);
  if (run_dc) bench_dual_contouring(cases, repeat);
  // Each method's rows: the CPU extractor and the two GL paths, same options.
  struct Runner {
    const char* method;
    std::function<Mesh(const VolumeView&, double)> cpu;
    std::function<Mesh(const VolumeView&, double, gl::McStats*)> gs, hp;
  };
  std::vector<Runner> runners;
  if (run_mc)
    runners.push_back(
        {"mc", [](const VolumeView& v, double iso) { return marching_cubes(v, {.iso = iso}); },
         [](const VolumeView& v, double iso, gl::McStats* s) {
           return gl::mc_geometry_shader(v, {.iso = iso}, s);
         },
         [](const VolumeView& v, double iso, gl::McStats* s) {
           return gl::mc_histopyramid(v, {.iso = iso}, s);
         }});
  if (run_macet) {
    auto o = [](double iso) {
      gl::MacetGlOptions m;
      m.macet.iso = iso;
      return m;
    };
    runners.push_back({"macet",
                       [](const VolumeView& v, double iso) { return macet(v, {.iso = iso}); },
                       [o](const VolumeView& v, double iso, gl::McStats* s) {
                         return gl::macet_geometry_shader(v, o(iso), s);
                       },
                       [o](const VolumeView& v, double iso, gl::McStats* s) {
                         return gl::macet_histopyramid(v, o(iso), s);
                       }});
  }

  struct Stages {
    std::string name;
    gl::McStats gs, hp, hpe;
    std::size_t triangles;
    double cpu, gs_s, hp_s, hpe_s;  // median whole-call seconds
  };
  std::vector<Stages> stages;
  for (const Runner& r : runners) {
    std::printf("\nmethod %s\n", r.method);
    std::printf("%-12s %10s %10s %10s %10s %10s %8s %8s %8s  %s\n", "volume", "triangles", "cpu ms",
                "gs ms", "hp ms", "hpe ms", "gs/cpu", "hp/cpu", "hpe/cpu", "same mesh");
    for (const Case& c : cases) {
      const VolumeView v = c.volume->view();
      Mesh cpu, gs, hp, hpe;
      const double t_cpu = median_seconds(
          repeat, [&] { return r.cpu(v, c.iso); }, cpu);
      r.gs(v, c.iso, nullptr);  // compile the shaders outside the timing
      const double t_gs = median_seconds(
          repeat, [&] { return r.gs(v, c.iso, nullptr); }, gs);
      r.hp(v, c.iso, nullptr);
      const double t_hp = median_seconds(
          repeat, [&] { return r.hp(v, c.iso, nullptr); }, hp);
      auto hp_per_element = [&] { return per_element([&] { return r.hp(v, c.iso, nullptr); }); };
      hp_per_element();
      const double t_hpe = median_seconds(repeat, hp_per_element, hpe);
      std::printf("%-12s %10zu %10.1f %10.1f %10.1f %10.1f %8.1f %8.1f %8.1f  %s\n", c.name.c_str(),
                  cpu.triangles.size(), 1e3 * t_cpu, 1e3 * t_gs, 1e3 * t_hp, 1e3 * t_hpe,
                  t_gs / t_cpu, t_hp / t_cpu, t_hpe / t_cpu,
                  same(cpu, gs) && same(cpu, hp) && same(cpu, hpe) ? "yes" : "NO");
      gl::McStats sg, sh, she;
      r.gs(v, c.iso, &sg);
      r.hp(v, c.iso, &sh);
      per_element([&] { return r.hp(v, c.iso, &she); });
      stages.push_back({std::string(r.method) + " " + c.name, sg, sh, she, cpu.triangles.size(),
                        t_cpu, t_gs, t_hp, t_hpe});
    }
  }
  // Where the GL time goes: one more run of each path, its stages from GL timer queries
  // (shaders/stage_clock.h, no glFinish), summed over slabs; upload GB/s from the same run;
  // triangles/s from the medians above.
  std::printf(
      "\nGL stages in ms (one run each: upload, prepare, classify, scan, vertices, faces, "
      "readback), upload GB/s, Mtriangles/s (medians)\n");
  std::printf("%-18s %-4s %8s %8s %8s %8s %8s %8s %8s %8s %10s\n", "method volume", "path",
              "upload", "prepare", "classify", "scan", "vertices", "faces", "readback", "GB/s",
              "Mtri/s");
  auto row = [](const std::string& name, const char* path, const gl::McStats& st,
                std::size_t triangles, double seconds) {
    const gl::GlTimes& t = st.times;
    const double up = t[gl::GlStage::Upload];
    std::printf("%-18s %-4s", name.c_str(), path);
    for (int i = 0; i < gl::kGlStageCount; ++i) std::printf(" %8.1f", 1e3 * t.seconds[i]);
    std::printf(" %8.2f %10.1f\n", up > 0 ? static_cast<double>(t.upload_bytes) / up / 1e9 : 0.0,
                static_cast<double>(triangles) / seconds / 1e6);
  };
  for (const Stages& st : stages) {
    std::printf("%-18s %-4s%72s %10.1f\n", st.name.c_str(), "cpu", "",
                static_cast<double>(st.triangles) / st.cpu / 1e6);
    row(st.name, "gs", st.gs, st.triangles, st.gs_s);
    row(st.name, "hp", st.hp, st.triangles, st.hp_s);
    row(st.name, "hpe", st.hpe, st.triangles, st.hpe_s);
  }
  return 0;
}
