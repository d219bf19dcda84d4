// The process's one headless OpenGL 4.5 core context, shared by the GL extractors, and its own
// thread.
//
// Created on first use, trying in turn: EGL's device platform with a hardware device (a real GPU,
// no window system needed), EGL's surfaceless platform (Mesa: llvmpipe on CPU-only machines), and
// OSMesa loaded with dlopen (so machines with a GPU need not have it). The context is made on a
// thread of its own, which keeps it current and runs the extractions (on_context_thread()): on
// NVIDIA's driver, taking a context on a thread after it was given back cost about 0.2 s
// (docs/gl.md), more than most extractions. A Scope on another thread borrows it from there.
// Without a surface every draw fails with GL_INVALID_FRAMEBUFFER_OPERATION, so a framebuffer object
// without attachments is bound once the context exists. Functions come from a glad loader generated
// at build time (see shaders/CMakeLists.txt; libepoxy aborts under OSMesa).
//
// Environment (for tests and diagnosis):
//   ISOTILE_GL=off                               no context: every GL backend reports unavailable
//   ISOTILE_GL=device|surfaceless|osmesa         try only that way
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace isotile::gl {

struct DeviceInfo {
  std::string platform;  // "egl-device", "egl-surfaceless" or "osmesa"
  // egl-device: which of the hardware EGL devices (0-based, in EGL's order), of how many, and why
  // that one (hardware_device_order()); -1, 0 and "" otherwise.
  int device_index = -1, device_count = 0;
  std::string device_chosen_by;
  std::string vendor, renderer, version, glsl_version;
  bool software = false;  // llvmpipe, softpipe, swrast, or an EGL device marked as software
  // Device memory in KiB from GL_NVX_gpu_memory_info or GL_ATI_meminfo; -1 when not told.
  std::int64_t memory_total_kib = -1, memory_free_kib = -1;
  std::int64_t max_ssbo_bytes = 0;            // GL_MAX_SHADER_STORAGE_BLOCK_SIZE
  std::int64_t max_compute_groups[3] = {};    // GL_MAX_COMPUTE_WORK_GROUP_COUNT
  std::int64_t max_gs_output_vertices = 0;    // GL_MAX_GEOMETRY_OUTPUT_VERTICES
  std::int64_t max_tf_interleaved = 0;        // GL_MAX_TRANSFORM_FEEDBACK_INTERLEAVED_COMPONENTS
  std::int64_t max_vertex_ssbo_blocks = 0;    // GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS
  std::int64_t max_geometry_ssbo_blocks = 0;  // GL_MAX_GEOMETRY_SHADER_STORAGE_BLOCKS
  std::int64_t max_3d_texture = 0;            // GL_MAX_3D_TEXTURE_SIZE
  // GL_NUM_PROGRAM_BINARY_FORMATS: 0 when programs cannot be saved (program_cache.h). Mesa
  // reports 1 when its own shader cache is on and 0 when it is off (MESA_SHADER_CACHE_DISABLE).
  std::int64_t program_binary_formats = 0;
  // Wall seconds the context's start-up took (EGL or OSMesa, the driver, the loader), every way
  // tried included.
  double startup_seconds = 0;
};

// The context's description; creates the context on first call. Throws InputError naming why
// each way of creating one failed (the same message on every later call).
const DeviceInfo& device();

// True when a context can be (or was) created; never throws. `why` gets the reason when not.
bool available(std::string* why = nullptr);

// Makes the context on its thread without waiting, so that the caller can go on (read its volume)
// meanwhile: the first Scope, device(), available() or on_context_thread() waits for it. Does
// nothing when the context exists, failed, or is being made; with ISOTILE_GL=off it fails at once,
// in the caller.
void start_context();

// Whether start_context() has begun making the context (since the last shutdown()), whatever
// came of it; takes no lock.
bool context_started();

// Why start_context()'s thread could not make the context, once it has finished failing; "" while
// it runs, when it succeeded, or when it was not started. Never waits for that thread.
std::string start_failure();

// The order in which the `count` hardware EGL devices are tried, and why: ISOTILE_GL_DEVICE=N
// names the one device to use (nothing else is tried, llvmpipe included); otherwise a process
// started by an MPI or Slurm launcher starts from its rank among the processes of its node
// (OMPI_COMM_WORLD_LOCAL_RANK, MPI_LOCALRANKID, MV2_COMM_WORLD_LOCAL_RANK, SLURM_LOCALID) modulo
// `count`, so that the ranks of a node with several GPUs spread over them; else from device 0.
// The others follow in turn, in case one cannot make a context. An empty order comes with `why`
// (ISOTILE_GL_DEVICE is not a number, or names a device that does not exist). Reads only the
// environment.
struct DeviceOrder {
  std::vector<int> order;
  std::string chosen_by;  // "ISOTILE_GL_DEVICE", "OMPI_COMM_WORLD_LOCAL_RANK=3", "first"
  std::string why;
};
DeviceOrder hardware_device_order(int count);

// True when EGL lists a hardware device (a GPU) that the context would use; cheap (no context is
// made), so that `--backend auto` on a machine without a GPU does not pay for starting llvmpipe.
bool hardware_device_present();

// Registers `release` to run, with the context current, when shutdown() ends the context: the
// objects kept for the context's life (programs, tables, vertex arrays) register their deletion
// here. Registering the same function again does nothing.
void at_shutdown(void (*release)());

// Ends this process's use of GL in a known order: runs the registered releases with the context
// current, deletes the context's framebuffer, destroys the context and terminates its EGL display
// (or destroys the OSMesa context), releases the EGL state of the context's thread and joins that
// thread. Afterwards no GL or EGL object is left to static destructors or to the drivers' own
// exit handlers (NVIDIA's libEGL corrupted the heap at exit while TBB's workers were still
// running: docs/gl.md). Call it once no thread uses GL any more; from a job on the context's
// thread, where it would wait for itself, it throws Error. The CLI calls it after joining TBB's
// workers, the MeshLab plugin when it is unloaded, and library users before leaving main(). A later
// GL call creates a new context and thread. Does nothing when no context exists.
void shutdown();

// Whether a context exists now (created and not shut down).
bool context_alive();

// How many times a thread made the context current in this process: its making, each Scope that
// borrowed it from the context's thread (an outermost one on its thread) and each job after such
// a Scope that took it back there. Extractions take nothing while no Scope borrows it. For tests.
int context_takes();

// Runs `job` on the context's thread with the context current there, and waits for it: its result
// is returned and what it throws is thrown here. Jobs run one at a time, in the caller's thread
// limit (its task_arena's concurrency). Where the calling thread has the context already (inside
// a Scope, or a job) the job runs in place. Creates the context when needed (throws like
// device()). The GL extractors' entries run through it.
void run_on_context_thread(const std::function<void()>& job);
template <class Job>
auto on_context_thread(Job&& job) -> std::invoke_result_t<Job&> {
  using R = std::invoke_result_t<Job&>;
  if constexpr (std::is_void_v<R>) {
    run_on_context_thread([&] { job(); });
  } else {
    std::optional<R> result;
    run_on_context_thread([&] { result.emplace(job()); });
    return std::move(*result);
  }
}

// Runs `job` on the context's thread with the context current there, without waiting: after the
// jobs handed over before it (start_context()'s making of the context), and before any later GL
// call of another thread, which waits for it. What it throws is dropped. Only once
// start_context() has begun or the context exists, and not from a thread that has the context
// (else it does nothing); nothing when the context could not be made. For work an extraction
// would do first and that can overlap the caller's reading of its volume (the GL backends'
// prepare_backend()).
void start_on_context_thread(std::function<void()> job);

// Holds the context current on the calling thread, and every other thread's GL work off it, for
// its lifetime: the outermost Scope of a thread borrows the context from the context's thread,
// and at its end releases it and, on EGL, the thread's EGL state (so that worker threads that ran
// GL keep nothing of the driver's when they exit). Inside a job on the context's thread a Scope
// costs nothing. Creates the context when needed (throws like device()).
class Scope {
 public:
  Scope();
  ~Scope();
  Scope(const Scope&) = delete;
  Scope& operator=(const Scope&) = delete;

 private:
  std::unique_lock<std::recursive_mutex> lock_;  // not taken on the context's thread
};

}  // namespace isotile::gl
