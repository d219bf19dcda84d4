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
// the --stats file. This file parses the command line and dispatches: each subcommand lives in
// tiler/cli/*_command.cpp, and the extraction's work in the library (tiler/pipeline.h).
#include <fcntl.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "core/version.h"
#ifdef ISOTILE_HAVE_GL
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#endif
#include "tiler/cli/cli_common.h"
#include "tiler/cli/commands.h"
#include "tiler/mpi_launch.h"
#include "tiler/render_command.h"

namespace {

using namespace isotile;
using namespace isotile::cli;

// Where a worker thread cannot be started (a process or memory limit: ulimit -u or -v, a
// container's pids.max), TBB throws "pthread_create has failed" from whichever call wanted the
// worker, and tbb::finalize then waits for that worker for ever (oneTBB 2021.8). Once it has been
// seen, main ends the process without finalize.
bool g_worker_start_failed = false;

bool worker_start_failure(const char* what) {
  return std::strstr(what, "pthread_create has failed") != nullptr;
}

// One error line. Under MPI only rank 0 prints: an error outside the distributed run comes from
// the arguments, which every rank shares, and one inside it is agreed on by all ranks, with the
// failing rank named. An error only this rank has inside the run (not agreed) aborts the job, as
// the other ranks wait for this one.
int fail(const char* what, bool agreed) {
  // On every rank: each one's finalize would wait.
  if (worker_start_failure(what)) g_worker_start_failed = true;
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
  if (worker_start_failure(what)) {
    std::fprintf(stderr,
                 "isotile: error: %s (a worker thread could not be started: raise the process or "
                 "memory limits, or give fewer --threads)\n",
                 what);
    return 1;
  }
  std::fprintf(stderr, "isotile: error: %s\n", what);
  return 1;
}

// The signals that end a run: Ctrl-C, kill, a closed terminal.
constexpr int kCancelSignals[] = {SIGINT, SIGTERM, SIGHUP};

// A signal the parent set to be ignored stays ignored (nohup's SIGHUP, a script's background
// job's SIGINT and SIGQUIT, a parent's ignored SIGPIPE, whose writes then fail as errors).
bool ignored_on_entry(int sig) {
  struct sigaction current {};
  return ::sigaction(sig, nullptr, &current) == 0 && current.sa_handler == SIG_IGN;
}
bool g_ignored[NSIG] = {};
void handle(int sig, void (*handler)(int)) {
  if (!g_ignored[sig]) std::signal(sig, handler);
}

// Signals whose default action ends the process other than the cancel signals: SIGQUIT (its core
// dump), SIGPIPE (stderr or stdout piped into a reader that stopped, as `2>&1 | head` does), a
// soft CPU-time limit's SIGXCPU (ulimit -t, a batch scheduler's), and the timers and user
// signals nothing here uses (SIGALRM until a cancel sets the grace timer's handler). Each left
// the output's hidden temporary behind.
constexpr int kEndingSignals[] = {SIGQUIT, SIGPIPE,   SIGXCPU, SIGUSR1,
                                  SIGUSR2, SIGVTALRM, SIGPROF, SIGALRM};

// A crash (this process's code or a library's: Mesa's llvmpipe under an address-space limit)
// removes the temporaries and says so in one line before the default action (the core dump).
// Not under a sanitizer, whose own report of the crash is the one to read.
extern "C" void on_crash(int sig) {
  // Built by hand: snprintf is not async-signal-safe.
  char line[96] = "isotile: error: crashed (signal ";
  std::size_t n = std::strlen(line);
  if (sig >= 10) line[n++] = static_cast<char>('0' + sig / 10);
  line[n++] = static_cast<char>('0' + sig % 10);
  static const char kRest[] = "); its unfinished files were removed\n";
  std::memcpy(line + n, kRest, sizeof kRest - 1);
  n += sizeof kRest - 1;
  [[maybe_unused]] const ssize_t written = ::write(2, line, n);
  remove_temporaries_and_reraise(sig);
}
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

// Every signal that ends the process removes the temporaries first, then takes its default
// action (remove_temporaries_and_reraise). SIGXFSZ is ignored instead: a write past the file-size
// limit (ulimit -f) then fails with EFBIG, which the writers report as an error ("File too large")
// and clean up after, as after a full disk.
void install_signal_handlers() {
  for (int sig : kCancelSignals) g_ignored[sig] = ignored_on_entry(sig);
  for (int sig : kEndingSignals) g_ignored[sig] = ignored_on_entry(sig);
  for (int sig : kCancelSignals) handle(sig, remove_temporaries_and_reraise);
  for (int sig : kEndingSignals) handle(sig, remove_temporaries_and_reraise);
  std::signal(SIGXFSZ, SIG_IGN);
  if (!kSanitized)
    for (int sig : {SIGSEGV, SIGBUS, SIGABRT, SIGFPE, SIGILL}) std::signal(sig, on_crash);
}

// A descriptor 0, 1 or 2 the caller closed (`2>&-`) would be the next file opened: the output's
// temporary, into which the progress lines on stderr then went, exit 0. Each closed one is held
// by /dev/null opened the other way (stdin for writing, stdout and stderr for reading), so that
// the descriptor stays taken and its use still fails as on a closed one: `--stats -` says
// standard output is not writable.
void hold_closed_standard_descriptors() {
  for (int fd = 0; fd < 3; ++fd) {
    if (::fcntl(fd, F_GETFD) >= 0 || errno != EBADF) continue;
    // The lowest free descriptor: this one, as the lower ones are open.
    const int held = ::open("/dev/null", (fd == 0 ? O_WRONLY : O_RDONLY) | O_NOCTTY);
    if (held != fd) {
      if (held >= 0) ::close(held);
      ::_exit(1);  // no /dev/null: nothing can be said or written safely
    }
  }
}

volatile std::sig_atomic_t g_cancel_signal = 0;

// A run blocked in a system call (reading a FIFO, a stalled network file system) does not reach
// its next unit of work, and glibc restarts the call after the handler: the cancel would never be
// seen. Seconds after the first signal the process ends as a second signal would end it.
constexpr unsigned kCancelGraceSeconds = 3;
extern "C" void on_cancel_timeout(int) {
  remove_pending_temporaries();
  static const char kMessage[] = "isotile: cancelled\n";
  [[maybe_unused]] const ssize_t n = ::write(2, kMessage, sizeof kMessage - 1);
  ::_exit(128 + static_cast<int>(g_cancel_signal));
}

// The first cancel signal (extract, simplify, demo) cancels the run through g_progress (only a
// lock-free atomic store here: async-signal-safe); the work stops at its next unit, its files are
// removed as the exception unwinds, and main prints "isotile: cancelled" and exits 128 + the
// signal. A second one ends the process at once (removing the temporaries), as does the grace
// period's end.
extern "C" void on_cancel_signal(int sig) {
  g_cancel_signal = sig;
  g_progress.cancel();
  for (int s : kCancelSignals) handle(s, remove_temporaries_and_reraise);
  std::signal(SIGALRM, on_cancel_timeout);
  ::alarm(kCancelGraceSeconds);
}

int cancelled() {
  ::alarm(0);
  std::fprintf(stderr, "isotile: cancelled\n");
  return 128 + (g_cancel_signal ? static_cast<int>(g_cancel_signal) : SIGINT);
}

// An error after a cancel signal comes of it (a system call the signal interrupted: "cannot open
// ...: Interrupted system call" where the call is not restarted, as under ThreadSanitizer): the
// run was cancelled, and says so. Under mpirun errors are agreed on by every rank, as before.
int failed_or_cancelled(const char* what) {
#ifdef ISOTILE_HAVE_MPI
  const bool distributed = g_mpi.has_value();
#else
  const bool distributed = false;
#endif
  if (g_cancel_signal != 0 && !distributed) return cancelled();
  return fail(what, false);
}

}  // namespace

// --threads: never destroyed: lifting the limit at the end can start workers, and where a worker
// cannot start the destructor's exception ends in std::terminate (seen with --threads 1 under
// ulimit -v). tbb::finalize joins the workers with the limit in place. Held by a pointer of
// external linkage, so that the store is kept and LeakSanitizer finds the object from it (in the
// anonymous namespace the optimizer dropped the unread store, and it counted as a leak).
tbb::global_control* g_isotile_thread_limit = nullptr;

int main(int argc, char** argv) {
  hold_closed_standard_descriptors();
  install_signal_handlers();
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
  app.set_version_flag("--version", "isotile " + std::string(isotile::version()));
  // Every option's default in --help (and so in the man page), inherited by the subcommands.
  app.option_defaults()->always_capture_default();
  int threads = 0;
  // Bounded: TBB reserves per-thread state up front, so a billion ended in "out of memory".
  app.add_option("--threads", threads, "Worker threads (0, the default: every core; at most 4096)")
      ->check(CLI::Range(0, 4096));
  app.add_flag("--quiet,-q", g_quiet, "No progress messages on stderr");

  ExtractArgs ex;
  auto* extract_cmd = add_extract_command(app, ex);
  InfoArgs info_args;
  auto* info_cmd = add_info_command(app, info_args);
  QualityArgs quality_args;
  auto* quality_cmd = add_quality_command(app, quality_args);
  SimplifyArgs sa;
  auto* simplify_cmd = add_simplify_command(app, sa);

  std::string demo_output = "isotile-demo.ply";
  auto* demo_cmd = app.add_subcommand(
      "demo", "Extract the built-in demo (a 128^3 gyroid) and print its statistics");
  demo_cmd->add_option("-o,--output", demo_output,
                       "Where to write the demo mesh: .ply, .obj, .stl or .off");

  // Subcommand options may also come before the subcommand name.
  bool gl_info_json = false;
  auto* gl_info_cmd = add_gl_info_command(app, gl_info_json);

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
    errno = 0;
    if (app.exit(e) != 0) return 2;
    // CLI11 ends --version's line with std::endl: a failure is met there, and its reason is
    // errno's now (the flush below fails again without setting it).
    const int printing = errno;
    try {
      flush_stdout(printing);
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

  tbb::task_scheduler_handle workers;
  try {
    if (threads > 0)
      g_isotile_thread_limit =
          new tbb::global_control(tbb::global_control::max_allowed_parallelism, threads);
    workers = tbb::task_scheduler_handle{tbb::attach{}};
  } catch (const std::bad_alloc&) {
    return fail("out of memory", false);
  }

  // The files of a run that writes several (extract, simplify, demo: the mesh, --stats, --render)
  // are renamed into place together at its end, once all went well: a run that failed or was
  // cancelled after its mesh was written (a stats file that cannot be written, a Ctrl-C during
  // the --stats measures or --render) had replaced the old mesh already.
  std::optional<HeldCommits> held;
  if (*extract_cmd || *simplify_cmd || *demo_cmd) held.emplace();
  // Whatever went to standard output must have reached it: a failed write is exit 1. A cancel
  // that came during a step without progress reports (the measures) cancels the run still.
  const auto finished = [&](int rc) {
    if (rc == 0) flush_stdout();
    if (rc == 0 && held) {
      g_progress.check();
      held->commit();
    }
    return rc;
  };
  // The commands whose work reports through g_progress are cancelled by the first signal; the
  // others end at it, as before. Under MPI each rank ends at the signal (mpirun forwards it to
  // every rank): a rank cancelling alone would leave the others waiting in a collective.
  if ((*extract_cmd || *simplify_cmd || *demo_cmd) && !launched_by_mpi()) {
    for (int sig : kCancelSignals) handle(sig, on_cancel_signal);
  }
  const int rc = [&]() -> int {
    try {
      if (*extract_cmd) return finished(run_extract(ex));
      if (*info_cmd) return finished(run_info(info_args));
      if (*gl_info_cmd) return finished(run_gl_info(gl_info_json));
      if (*quality_cmd) return finished(run_quality(quality_args));
      if (*simplify_cmd) return finished(run_simplify(sa));
      if (*render_cmd) return finished(run_render(render_args, g_quiet));
      if (*demo_cmd) {
        ExtractArgs d;
        d.in.input = "field:gyroid:128";
        d.output = demo_output;
        d.stats = "-";
        // Said here in demo's words: it has no --stats option to name.
        if (same_file("/dev/stdout", demo_output))
          throw InputError("standard output, where demo prints its statistics, is the output " +
                           demo_output +
                           " (one would replace the other): redirect it elsewhere, or write the "
                           "mesh elsewhere with -o");
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
    } catch (const isotile::Cancelled&) {
      return cancelled();
    } catch (const isotile::Error& e) {
      return failed_or_cancelled(e.what());
    } catch (const std::bad_alloc&) {
      return failed_or_cancelled("out of memory");
    } catch (const std::exception& e) {
      return failed_or_cancelled(e.what());
    }
    return 0;
  }();
  // The work is over (a cancel that came too late for it changes nothing now); what it held and
  // did not commit is removed.
  ::alarm(0);
  held.reset();

  // A known order at the end (docs/gl.md): TBB's workers joined, then the GL context and what was
  // made on it deleted, before exit() runs static destructors and the drivers' own exit handlers.
  if (g_worker_start_failed) {
    // The outputs are complete or removed already; only finalize's endless wait is skipped.
    std::fflush(stdout);
    std::fflush(stderr);
    std::_Exit(rc);
  }
  tbb::finalize(workers, std::nothrow);
#ifdef ISOTILE_HAVE_GL
  isotile::gl::shutdown();
#endif
  return rc;
}
