#include "gl_context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <dlfcn.h>
#include <glad/gl.h>
#include <link.h>

#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <functional>
#include <memory>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "core/errors.h"

namespace isotile::gl {

namespace {

// OSMesa's interface, declared here because the library is dlopen'ed (osmesa.h would make us link
// it). Values from GL/osmesa.h.
using OSMesaContext = void*;
constexpr int kOsmesaFormat = 0x22, kOsmesaRgba = 0x1908, kOsmesaDepthBits = 0x30,
              kOsmesaStencilBits = 0x31, kOsmesaAccumBits = 0x32, kOsmesaProfile = 0x33,
              kOsmesaCoreProfile = 0x34, kOsmesaMajor = 0x36, kOsmesaMinor = 0x37;
using OsmesaCreateFn = OSMesaContext (*)(const int*, OSMesaContext);
using OsmesaMakeCurrentFn = unsigned char (*)(OSMesaContext, void*, unsigned, int, int);
using OsmesaGetProcFn = GLADapiproc (*)(const char*);
using OsmesaDestroyFn = void (*)(OSMesaContext);

// Keeps the Mesa DRI drivers loaded now loaded until the process ends. eglTerminate unloads
// them, and their own allocations, referenced only from their globals, would then read as leaks
// to LeakSanitizer (the sanitizer pass fails on them); loaded, they stay reachable, as they did
// before shutdown() existed. The handles are kept on purpose (RTLD_NODELETE).
void pin_dri_drivers() {
  std::vector<std::string> drivers;
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void* out) {
        const std::string_view name = info->dlpi_name ? info->dlpi_name : "";
        if (name.find("/dri/") != std::string_view::npos && name.ends_with("_dri.so"))
          static_cast<std::vector<std::string>*>(out)->emplace_back(name);
        return 0;
      },
      &drivers);
  // dlopen outside the iteration, which holds the loader's lock.
  for (const std::string& d : drivers) dlopen(d.c_str(), RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
}

struct Context {
  DeviceInfo info;
  // EGL
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext egl = EGL_NO_CONTEXT;
  // OSMesa
  OSMesaContext osmesa = nullptr;
  OsmesaMakeCurrentFn osmesa_make_current = nullptr;
  OsmesaDestroyFn osmesa_destroy = nullptr;
  unsigned char pixel[4] = {};
  GLuint framebuffer = 0;

  bool make_current() {
    if (osmesa) return osmesa_make_current(osmesa, pixel, GL_UNSIGNED_BYTE, 1, 1);
    return eglBindAPI(EGL_OPENGL_API) &&
           eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, egl) == EGL_TRUE;
  }
  void release() {
    if (osmesa)
      osmesa_make_current(nullptr, nullptr, 0, 0, 0);
    else
      eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  }
  // Releases this thread's EGL state (current context, bound API); the next make_current()
  // binds the OpenGL API again.
  void release_thread() {
    release();
    if (!osmesa) eglReleaseThread();
  }
  // The context and its display, after release().
  void destroy() {
    pin_dri_drivers();
    if (osmesa) {
      if (osmesa_destroy) osmesa_destroy(osmesa);
      osmesa = nullptr;
      return;
    }
    if (egl != EGL_NO_CONTEXT) eglDestroyContext(display, egl);
    egl = EGL_NO_CONTEXT;
    if (display != EGL_NO_DISPLAY) eglTerminate(display);
    display = EGL_NO_DISPLAY;
    eglReleaseThread();
  }
};

std::recursive_mutex g_mutex;
std::unique_ptr<Context> g_context;  // set once created; lives until shutdown()
std::vector<void (*)()> g_releases;  // at_shutdown()
std::string g_failure;               // set once creation failed
thread_local int t_depth = 0;
int g_takes = 0;  // context_takes()
// start_context(): true from its call to shutdown().
std::atomic<bool> g_started{false};
// Set by the context's thread when start_context()'s making of the context failed (g_failure says
// why), so that start_failure() need not wait for that thread.
std::atomic<bool> g_start_failed{false};

// The context's own thread: it makes the context and keeps it current between the jobs it is
// handed (on_context_thread()), so that an extraction takes nothing (on NVIDIA's driver taking
// the context on a thread after it was given back cost about 0.2 s, docs/gl.md). It runs its jobs
// one at a time in the order handed over, each by a thread that holds g_mutex and waits for it,
// so a job uses the state below as its caller's deputy, without taking g_mutex itself
// (StateLock). The jobs nobody waits for are start_context()'s making of the context and
// start_on_context_thread()'s; whoever takes g_mutex next waits for them first (settle()).
class ContextThread {
 public:
  ContextThread() : thread_([this] { serve(); }) {}
  // Queues `job` behind those handed over before, and returns at once.
  void post(std::function<void()> job) {
    {
      std::lock_guard lock(mutex_);
      jobs_.push_back(std::move(job));
    }
    changed_.notify_all();
  }
  // Returns once every job handed over has run.
  void wait() {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [&] { return jobs_.empty() && !running_; });
  }
  // Runs `job` there and waits for it.
  void run(std::function<void()> job) {
    post(std::move(job));
    wait();
  }
  void stop_and_join() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }

 private:
  void serve();

  std::mutex mutex_;
  std::condition_variable changed_, idle_;
  std::deque<std::function<void()>> jobs_;  // handed over and not yet begun
  bool running_ = false;                    // a job has begun and not ended
  bool stop_ = false;
  std::thread thread_;
};

// Made on first use and ended by shutdown(). Where a program never calls shutdown(), the thread
// is left parked at exit (never destroyed, so never joined) and ends with the process, like the
// context, which no exit handler of ours touches.
ContextThread* g_thread = nullptr;
thread_local bool t_context_thread = false;  // set on the context's thread
bool g_current_there = false;                // the context is current on the context's thread

void ContextThread::serve() {
  t_context_thread = true;
  std::unique_lock lock(mutex_);
  for (;;) {
    changed_.wait(lock, [&] { return !jobs_.empty() || stop_; });
    if (jobs_.empty()) return;
    std::function<void()> job = std::move(jobs_.front());
    jobs_.pop_front();
    running_ = true;
    lock.unlock();
    job();  // jobs catch what they throw
    job = nullptr;
    lock.lock();
    running_ = false;
    if (jobs_.empty()) idle_.notify_all();
  }
}

ContextThread& context_thread() {
  if (!g_thread) g_thread = new ContextThread;
  return *g_thread;
}

// The jobs nobody waits for (start_context()'s, start_on_context_thread()'s), if they have not yet
// run: wait for them. Caller holds g_mutex.
void settle() {
  if (g_thread) g_thread->wait();
}

// g_mutex for the state above, taken and settled; on the context's thread nothing, its job's
// caller holding it.
class StateLock {
 public:
  StateLock() {
    if (t_context_thread) return;
    lock_ = std::unique_lock(g_mutex);
    settle();
  }

 private:
  std::unique_lock<std::recursive_mutex> lock_;
};

bool has_word(const char* list, std::string_view word) {
  if (!list) return false;
  std::string_view s(list);
  for (std::size_t pos = 0; (pos = s.find(word, pos)) != std::string_view::npos;
       pos += word.size()) {
    const bool start = pos == 0 || s[pos - 1] == ' ';
    const bool end = pos + word.size() == s.size() || s[pos + word.size()] == ' ';
    if (start && end) return true;
  }
  return false;
}

std::string egl_error(const char* what) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%s failed (EGL error 0x%04x)", what, eglGetError());
  return buf;
}

// A 4.5 core context on an initialised EGL display, current on this thread.
bool egl_context_on(EGLDisplay display, Context& c, std::string& why) {
  EGLint major = 0, minor = 0;
  if (!eglInitialize(display, &major, &minor)) return why = egl_error("eglInitialize"), false;
  if (!eglBindAPI(EGL_OPENGL_API)) return why = egl_error("eglBindAPI(OpenGL)"), false;
  EGLConfig config = nullptr;  // EGL_NO_CONFIG_KHR where the display supports it
  const char* exts = eglQueryString(display, EGL_EXTENSIONS);
  if (!has_word(exts, "EGL_KHR_no_config_context")) {
    const EGLint attrs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE, EGL_PBUFFER_BIT,
                            EGL_NONE};
    EGLint n = 0;
    if (!eglChooseConfig(display, attrs, &config, 1, &n) || n < 1)
      return why = "no OpenGL-capable EGL config", false;
  }
  const EGLint ctx_attrs[] = {EGL_CONTEXT_MAJOR_VERSION,
                              4,
                              EGL_CONTEXT_MINOR_VERSION,
                              5,
                              EGL_CONTEXT_OPENGL_PROFILE_MASK,
                              EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                              EGL_NONE};
  EGLContext ctx = eglCreateContext(display, config, EGL_NO_CONTEXT, ctx_attrs);
  if (ctx == EGL_NO_CONTEXT) return why = egl_error("eglCreateContext(OpenGL 4.5 core)"), false;
  if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
    why = egl_error("eglMakeCurrent without a surface");
    eglDestroyContext(display, ctx);
    return false;
  }
  c.display = display;
  c.egl = ctx;
  return true;
}

GLADapiproc egl_proc(const char* name) {
  return eglGetProcAddress(name);
}

// The hardware EGL devices (not EGL_MESA_device_software), in EGL's order; `why` gets the reason
// when there are none.
std::vector<EGLDeviceEXT> hardware_devices(std::string* why = nullptr) {
  auto query_devices =
      reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
  auto device_string = reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(
      eglGetProcAddress("eglQueryDeviceStringEXT"));
  std::string reason = "EGL_EXT_device_enumeration is not supported";
  std::vector<EGLDeviceEXT> hardware;
  EGLDeviceEXT devices[16];
  EGLint n = 0;
  if (query_devices && device_string) {
    reason = "no EGL device";
    if (query_devices(16, devices, &n) && n > 0)
      reason = "no hardware EGL device (only software ones)";
    for (EGLint i = 0; i < n; ++i)
      if (!has_word(device_string(devices[i], EGL_EXTENSIONS), "EGL_MESA_device_software"))
        hardware.push_back(devices[i]);
  }
  if (hardware.empty() && why) *why = reason;
  return hardware;
}

bool try_egl_device(Context& c, std::string& why) {
  auto platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
      eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!platform_display) return why = "EGL_EXT_platform_base is not supported", false;
  const std::vector<EGLDeviceEXT> hardware = hardware_devices(&why);
  const DeviceOrder order = hardware_device_order(static_cast<int>(hardware.size()));
  if (!order.why.empty()) return why = order.why, false;
  for (const int k : order.order) {
    EGLDisplay d = platform_display(EGL_PLATFORM_DEVICE_EXT, hardware[k], nullptr);
    if (d == EGL_NO_DISPLAY) {
      why = egl_error(("eglGetPlatformDisplayEXT(device " + std::to_string(k) + ")").c_str());
      continue;
    }
    if (egl_context_on(d, c, why)) {
      c.info.platform = "egl-device";
      c.info.device_index = k;
      c.info.device_count = static_cast<int>(hardware.size());
      c.info.device_chosen_by = k == order.order.front() ? order.chosen_by : "the next that works";
      return gladLoadGL(egl_proc) != 0 || (why = "loading OpenGL functions failed", false);
    }
    eglTerminate(d);
  }
  return false;
}

bool try_egl_surfaceless(Context& c, std::string& why) {
  auto platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
      eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!platform_display ||
      !has_word(eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS), "EGL_MESA_platform_surfaceless"))
    return why = "EGL_MESA_platform_surfaceless is not supported", false;
  EGLDisplay d = platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (d == EGL_NO_DISPLAY) return why = egl_error("eglGetPlatformDisplayEXT(surfaceless)"), false;
  if (!egl_context_on(d, c, why)) {
    eglTerminate(d);
    return false;
  }
  c.info.platform = "egl-surfaceless";
  return gladLoadGL(egl_proc) != 0 || (why = "loading OpenGL functions failed", false);
}

OsmesaGetProcFn g_osmesa_proc = nullptr;
GLADapiproc osmesa_proc(const char* name) {
  return g_osmesa_proc(name);
}

// The Gallium drivers Debian's OSMesa is built with.
constexpr std::string_view kOsmesaDrivers[] = {"llvmpipe", "softpipe"};

// Why OSMesa must not be asked for a context in this environment, or "". Debian's OSMesa (Mesa
// 22.3) dies of SIGSEGV inside OSMesaCreateContextAttribs, where it should fail, when
// GALLIUM_DRIVER names a driver it does not have (a typo, "zink" without Vulkan: a null screen)
// and when MESA_GLSL_VERSION_OVERRIDE is below 140; neither can give a 4.5 context with GLSL 4.50
// (every override below 450 fails anyway), so both are refused with the variable's name.
std::string osmesa_refusal() {
  if (const char* g = std::getenv("GALLIUM_DRIVER"); g && *g) {
    const std::string_view name = g;
    if (std::find(std::begin(kOsmesaDrivers), std::end(kOsmesaDrivers), name) ==
        std::end(kOsmesaDrivers))
      return "GALLIUM_DRIVER='" + std::string(name) +
             "' names no driver OSMesa has (llvmpipe, softpipe)";
  }
  if (const char* v = std::getenv("MESA_GLSL_VERSION_OVERRIDE"); v && *v) {
    char* end = nullptr;
    const long glsl = std::strtol(v, &end, 10);
    if (end != v && glsl < 450)
      return "MESA_GLSL_VERSION_OVERRIDE=" + std::string(v) +
             " is below the GLSL 4.50 that isotile's programs need";
  }
  return {};
}

bool try_osmesa(Context& c, std::string& why) {
  if (std::string refused = osmesa_refusal(); !refused.empty())
    return why = std::move(refused), false;
  void* lib = dlopen("libOSMesa.so.8", RTLD_NOW | RTLD_LOCAL);
  if (!lib) lib = dlopen("libOSMesa.so", RTLD_NOW | RTLD_LOCAL);
  if (!lib) return why = "libOSMesa.so.8 not found (Debian: libosmesa6)", false;
  auto create = reinterpret_cast<OsmesaCreateFn>(dlsym(lib, "OSMesaCreateContextAttribs"));
  auto make_current = reinterpret_cast<OsmesaMakeCurrentFn>(dlsym(lib, "OSMesaMakeCurrent"));
  g_osmesa_proc = reinterpret_cast<OsmesaGetProcFn>(dlsym(lib, "OSMesaGetProcAddress"));
  if (!create || !make_current || !g_osmesa_proc)
    return why = "libOSMesa lacks OSMesaCreateContextAttribs", false;
  const int attrs[] = {kOsmesaFormat,
                       kOsmesaRgba,
                       kOsmesaDepthBits,
                       0,
                       kOsmesaStencilBits,
                       0,
                       kOsmesaAccumBits,
                       0,
                       kOsmesaProfile,
                       kOsmesaCoreProfile,
                       kOsmesaMajor,
                       4,
                       kOsmesaMinor,
                       5,
                       0};
  c.osmesa = create(attrs, nullptr);
  if (!c.osmesa) return why = "OSMesaCreateContextAttribs(OpenGL 4.5 core) failed", false;
  c.osmesa_make_current = make_current;
  c.osmesa_destroy = reinterpret_cast<OsmesaDestroyFn>(dlsym(lib, "OSMesaDestroyContext"));
  if (!c.make_current()) return why = "OSMesaMakeCurrent failed", false;
  c.info.platform = "osmesa";
  return gladLoadGL(osmesa_proc) != 0 || (why = "loading OpenGL functions failed", false);
}

std::int64_t get_int(GLenum e) {
  GLint64 v = 0;
  glGetInteger64v(e, &v);
  return v;
}

const char* gl_string(GLenum e) {
  const auto* s = reinterpret_cast<const char*>(glGetString(e));
  return s ? s : "";
}

void describe(Context& c) {
  DeviceInfo& i = c.info;
  i.vendor = gl_string(GL_VENDOR);
  i.renderer = gl_string(GL_RENDERER);
  i.version = gl_string(GL_VERSION);
  i.glsl_version = gl_string(GL_SHADING_LANGUAGE_VERSION);
  for (const char* sw : {"llvmpipe", "softpipe", "swrast", "SWR", "lavapipe"})
    if (i.renderer.find(sw) != std::string::npos) i.software = true;
  GLint n_ext = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n_ext);
  bool nvx = false, ati = false;
  for (GLint e = 0; e < n_ext; ++e) {
    const std::string_view name = reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, e));
    nvx = nvx || name == "GL_NVX_gpu_memory_info";
    ati = ati || name == "GL_ATI_meminfo";
  }
  if (nvx) {
    i.memory_total_kib = get_int(GL_GPU_MEMORY_INFO_TOTAL_AVAILABLE_MEMORY_NVX);
    i.memory_free_kib = get_int(GL_GPU_MEMORY_INFO_CURRENT_AVAILABLE_VIDMEM_NVX);
  } else if (ati) {
    GLint v[4] = {};
    glGetIntegerv(GL_VBO_FREE_MEMORY_ATI, v);  // v[0]: total free in the pool, KiB
    i.memory_free_kib = v[0];
  }
  i.max_ssbo_bytes = get_int(GL_MAX_SHADER_STORAGE_BLOCK_SIZE);
  for (GLuint a = 0; a < 3; ++a) {
    GLint v = 0;
    glGetIntegeri_v(GL_MAX_COMPUTE_WORK_GROUP_COUNT, a, &v);
    i.max_compute_groups[a] = v;
  }
  i.max_gs_output_vertices = get_int(GL_MAX_GEOMETRY_OUTPUT_VERTICES);
  i.max_tf_interleaved = get_int(GL_MAX_TRANSFORM_FEEDBACK_INTERLEAVED_COMPONENTS);
  i.max_vertex_ssbo_blocks = get_int(GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS);
  i.max_geometry_ssbo_blocks = get_int(GL_MAX_GEOMETRY_SHADER_STORAGE_BLOCKS);
  i.max_3d_texture = get_int(GL_MAX_3D_TEXTURE_SIZE);
  i.program_binary_formats = get_int(GL_NUM_PROGRAM_BINARY_FORMATS);
}

// Creates the context (current on this thread) or records why not. Caller holds g_mutex.
void create() {
  if (g_context || !g_failure.empty()) return;
  const auto start = std::chrono::steady_clock::now();
  const char* env = std::getenv("ISOTILE_GL");
  const std::string only = env ? env : "";
  if (only == "off") {
    g_failure = "no OpenGL context: disabled by ISOTILE_GL=off";
    return;
  }
  // A device named by number is that GPU or nothing: no other way is tried.
  std::string only_way = only;
  if (const char* d = std::getenv("ISOTILE_GL_DEVICE"); d && *d) {
    if (!only.empty() && only != "device") {
      g_failure =
          "no OpenGL context: ISOTILE_GL_DEVICE names a hardware EGL device, but "
          "ISOTILE_GL='" +
          only + "' asks for another way";
      return;
    }
    only_way = "device";
  }
  struct Way {
    const char* name;
    bool (*fn)(Context&, std::string&);
  };
  const Way ways[] = {
      {"device", try_egl_device}, {"surfaceless", try_egl_surfaceless}, {"osmesa", try_osmesa}};
  std::string reasons;
  for (const Way& w : ways) {
    if (!only_way.empty() && only_way != w.name) continue;
    auto c = std::make_unique<Context>();
    std::string why;
    if (w.fn(*c, why)) {
      glCreateFramebuffers(1, &c->framebuffer);
      glNamedFramebufferParameteri(c->framebuffer, GL_FRAMEBUFFER_DEFAULT_WIDTH, 1);
      glNamedFramebufferParameteri(c->framebuffer, GL_FRAMEBUFFER_DEFAULT_HEIGHT, 1);
      glBindFramebuffer(GL_FRAMEBUFFER, c->framebuffer);
      describe(*c);
      if (glGetError() == GL_NO_ERROR) {
        c->info.startup_seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        g_context = std::move(c);
        return;
      }
      why = "setting up the context raised a GL error";
    }
    if (!reasons.empty()) reasons += "; ";
    reasons += w.name;
    reasons += ": ";
    reasons += why;
  }
  if (reasons.empty())
    reasons = "ISOTILE_GL='" + only + "' names no way (device, surfaceless, osmesa, off)";
  g_failure = "no usable OpenGL 4.5 context (" + reasons + ")";
}

// On the context's thread: makes the context there and leaves it current, or records why not.
void make_context_there() {
  try {
    create();
  } catch (const std::exception& e) {  // nothing may leave the thread
    g_failure = std::string("no usable OpenGL 4.5 context: ") + e.what();
  } catch (...) {
    g_failure = "no usable OpenGL 4.5 context: an unknown error";
  }
  if (!g_context) return;
  ++g_takes;
  g_current_there = true;
}

// For a holder of g_mutex: the context, made on its thread where it is not made yet; false when
// it cannot be (g_failure says why).
bool ensure_context() {
  if (g_context) return true;
  if (!g_failure.empty()) return false;
  if (t_context_thread)
    make_context_there();
  else
    context_thread().run(make_context_there);
  return g_context != nullptr;
}

}  // namespace

bool hardware_device_present() {
  StateLock lock;
  if (g_context) return g_context->info.platform == "egl-device" && !g_context->info.software;
  if (!g_failure.empty()) return false;
  const char* env = std::getenv("ISOTILE_GL");
  if (env && std::string_view(env) != "device") return false;
  return !hardware_devices().empty();
}

void start_context() {
  StateLock lock;
  if (g_context || !g_failure.empty() || g_started) return;
  if (const char* env = std::getenv("ISOTILE_GL"); env && std::string_view(env) == "off") {
    create();  // records the failure: nothing to wait for
    return;
  }
  g_started = true;
  context_thread().post([] {
    make_context_there();
    if (!g_context) g_start_failed = true;
  });
}

bool context_started() {
  return g_started;
}

std::string start_failure() {
  if (!g_start_failed) return {};
  StateLock lock;
  return g_failure;
}

DeviceOrder hardware_device_order(int count) {
  DeviceOrder o;
  if (const char* env = std::getenv("ISOTILE_GL_DEVICE"); env && *env) {
    const std::string v = env;
    if (v.find_first_not_of("0123456789") != std::string::npos)
      return o.why = "ISOTILE_GL_DEVICE='" + v + "' is not a device number (0, 1, ...)", o;
    const long k = std::strtol(env, nullptr, 10);  // digits only: LONG_MAX at worst
    if (k >= count)
      return o.why = "ISOTILE_GL_DEVICE=" + v + ", but EGL lists " + std::to_string(count) +
                     " hardware device" + (count == 1 ? "" : "s") +
                     (count > 0 ? " (0 to " + std::to_string(count - 1) + ")" : ""),
             o;
    o.order = {static_cast<int>(k)};
    o.chosen_by = "ISOTILE_GL_DEVICE";
    return o;
  }
  int first = 0;
  o.chosen_by = "first";
  // The launchers' node-local ranks: Open MPI, MPICH's Hydra, MVAPICH, Slurm's srun.
  for (const char* name : {"OMPI_COMM_WORLD_LOCAL_RANK", "MPI_LOCALRANKID",
                           "MV2_COMM_WORLD_LOCAL_RANK", "SLURM_LOCALID"}) {
    const char* env = std::getenv(name);
    if (!env || !*env || count == 0) continue;
    char* end = nullptr;
    const long rank = std::strtol(env, &end, 10);
    if (*end != '\0' || rank < 0) continue;
    first = static_cast<int>(rank % count);
    o.chosen_by = std::string(name) + "=" + env;
    break;
  }
  for (int i = 0; i < count; ++i) o.order.push_back((first + i) % count);
  return o;
}

// The description was filled when the context was made: no GL call, only the lock.
const DeviceInfo& device() {
  StateLock lock;
  if (!ensure_context()) throw InputError(g_failure);
  return g_context->info;
}

bool available(std::string* why) {
  StateLock lock;
  if (!g_context && g_failure.empty()) ensure_context();
  if (why) *why = g_failure;
  return g_context != nullptr;
}

Scope::Scope() {
  if (t_context_thread) {  // a job there: the context is current
    ++t_depth;
    return;
  }
  lock_ = std::unique_lock(g_mutex);
  settle();
  if (t_depth == 0) {
    if (!ensure_context()) throw InputError(g_failure);
    // Lent by the context's thread, which takes it back with its next job.
    if (g_current_there)
      context_thread().run([] {
        g_context->release();
        g_current_there = false;
      });
    ++g_takes;
    if (!g_context->make_current()) throw Error("OpenGL: making the context current failed");
  }
  ++t_depth;
}

Scope::~Scope() {
  if (--t_depth == 0 && !t_context_thread && g_context) g_context->release_thread();
}

namespace {

// On the context's thread: `job` with the context current (taken back where a Scope on another
// thread had it) and the caller's thread limit for its parallel loops. Throws what the job
// throws, or Error where the context cannot be made current.
void run_there(const std::function<void()>& job, int concurrency) {
  if (!g_current_there) {  // back from a Scope elsewhere
    ++g_takes;
    if (!g_context->make_current()) throw Error("OpenGL: making the context current failed");
    g_current_there = true;
  }
  t_depth = 1;
  try {
    tbb::task_arena(concurrency).execute(job);
  } catch (...) {
    t_depth = 0;
    throw;
  }
  t_depth = 0;
}

}  // namespace

void run_on_context_thread(const std::function<void()>& job) {
  if (t_depth > 0) return job();  // the context is current here: a Scope, or a job there
  StateLock lock;
  if (!ensure_context()) throw InputError(g_failure);
  // The caller's thread limit (a task_arena's, as the Python module's `threads`) for the job's
  // parallel loops, which would otherwise run in the context thread's own default arena.
  const int concurrency = tbb::this_task_arena::max_concurrency();
  std::exception_ptr error;
  context_thread().run([&] {
    try {
      run_there(job, concurrency);
    } catch (...) {
      error = std::current_exception();
    }
  });
  if (error) std::rethrow_exception(error);
}

void start_on_context_thread(std::function<void()> job) {
  // Where this thread has the context, a job there could not make it current.
  if (t_depth > 0 || t_context_thread) return;
  // Not settled: the context may still be in the making, which this job follows.
  std::lock_guard lock(g_mutex);
  // Begun by start_context(), or made before (then no job that writes g_context is pending).
  if (!g_started && !g_context) return;
  const int concurrency = tbb::this_task_arena::max_concurrency();
  context_thread().post([job = std::move(job), concurrency] {
    if (!g_context) return;  // its making failed: the extraction says why
    try {
      run_there(job, concurrency);
    } catch (...) {
      // Dropped: what failed here fails again, and is reported, in the extraction.
    }
  });
}

void at_shutdown(void (*release)()) {
  StateLock lock;
  if (std::find(g_releases.begin(), g_releases.end(), release) == g_releases.end())
    g_releases.push_back(release);
}

void shutdown() {
  // It would wait for the job it runs in (and then join its own thread).
  if (t_context_thread) throw Error("gl::shutdown() called from a job on the GL context's thread");
  std::unique_lock lock(g_mutex);
  settle();
  g_started = false;
  // The registered releases need the context current: where this thread holds a Scope it is
  // current here, else on the context's thread (made current there when a Scope had it).
  auto end = [](bool current) {
    Context& c = *g_context;
    if (current) {
      for (auto release : g_releases) release();
      if (c.framebuffer) glDeleteFramebuffers(1, &c.framebuffer);
      c.framebuffer = 0;
      glFinish();
    }
    c.release();
    c.destroy();
    g_context.reset();
    g_current_there = false;
  };
  if (g_context && t_depth > 0)
    end(true);
  else if (g_context)
    context_thread().run([&] { end(g_current_there || g_context->make_current()); });
  if (g_thread) {
    g_thread->stop_and_join();
    delete g_thread;
    g_thread = nullptr;
  }
}

int context_takes() {
  StateLock lock;
  return g_takes;
}

bool context_alive() {
  StateLock lock;
  return g_context != nullptr;
}

}  // namespace isotile::gl
