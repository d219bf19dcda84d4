// Ctrl-C: the first SIGINT (or SIGTERM, SIGHUP) cancels the run through the library's Progress;
// the CLI says "isotile: cancelled", exits 128 + the signal (130 for SIGINT) and leaves no output
// and no temporary file. The signal is sent once stderr shows progress, so the run is inside a
// long loop. Other signals that end the process (SIGPIPE) remove the temporaries too.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "test_support.h"

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct Cancelled {
  int status = -1;
  std::string err;
  std::vector<std::string> left;  // names in the work directory afterwards
  double seconds = 0;             // from the start to the end of the process
};

// Runs `isotile ARGS...` in `dir`, waits until its stderr holds `marker` (an empty marker: for
// half a second), sends `sig` and collects the exit status and stderr. SIGPIPE is "sent" by
// closing the pipe its stderr goes to, so that its next progress line meets it. `ignored`: a
// signal the process starts with ignored (as nohup leaves SIGHUP). Gives up (killing it) after
// 120 s.
Cancelled run_and_signal(const fs::path& dir, const std::vector<std::string>& args,
                         const std::string& marker, int sig, int ignored = 0) {
  int pipe_fd[2];
  if (::pipe(pipe_fd) != 0) return {};
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(pipe_fd[1], 2);
    ::close(pipe_fd[0]);
    ::close(pipe_fd[1]);
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    if (ignored) ::signal(ignored, SIG_IGN);
    std::vector<char*> argv;
    std::string cli = ISOTILE_CLI;
    argv.push_back(cli.data());
    std::vector<std::string> copy = args;
    for (std::string& a : copy) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(cli.c_str(), argv.data());
    ::_exit(127);
  }
  ::close(pipe_fd[1]);
  Cancelled r;
  bool sent = false;
  const auto t0 = Clock::now();
  char buf[4096];
  for (;;) {
    pollfd p{pipe_fd[0], POLLIN, 0};
    const int ready = ::poll(&p, 1, 100);
    if (ready > 0) {
      const ssize_t n = ::read(pipe_fd[0], buf, sizeof buf);
      if (n <= 0) break;  // the process closed stderr: it ended
      r.err.append(buf, static_cast<std::size_t>(n));
    }
    const bool due = marker.empty() ? Clock::now() - t0 > std::chrono::milliseconds(500)
                                    : r.err.find(marker) != std::string::npos;
    if (!sent && due) {
      sent = true;
      if (sig == SIGPIPE) break;
      ::kill(pid, sig);
    }
    if (Clock::now() - t0 > std::chrono::seconds(120)) {
      ::kill(pid, SIGKILL);
      break;
    }
  }
  ::close(pipe_fd[0]);
  // After SIGPIPE's close the process runs on until it writes to stderr: bounded too.
  for (int waited = 0; ::waitpid(pid, &r.status, WNOHANG) == 0; ++waited) {
    if (waited == 1200) ::kill(pid, SIGKILL);
    ::usleep(100000);
  }
  EXPECT_TRUE(sent) << "no progress line '" << marker << "' on stderr:\n" << r.err;
  for (const auto& e : fs::directory_iterator(dir)) r.left.push_back(e.path().filename().string());
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return r;
}

class CliCancel : public isotile::testing::TempDirTest {
 protected:
  CliCancel() : TempDirTest("isotile-cancel-") {}
};

void expect_cancelled(const Cancelled& r, int code) {
  ASSERT_TRUE(WIFEXITED(r.status)) << "did not exit (signal " << WTERMSIG(r.status) << "):\n"
                                   << r.err;
  EXPECT_EQ(WEXITSTATUS(r.status), code) << r.err;
  EXPECT_NE(r.err.find("isotile: cancelled\n"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("error"), std::string::npos) << r.err;
  EXPECT_TRUE(r.left.empty()) << "left behind: " << r.left.front();
}

// Macet max on a 256^3 gyroid runs for seconds; SIGINT during its search, and SIGHUP (a closed
// terminal), which cancels as SIGINT and SIGTERM do.
TEST_F(CliCancel, SigintDuringExtractionExits130AndLeavesNothing) {
  for (const auto& [sig, code] : {std::pair{SIGINT, 130}, std::pair{SIGHUP, 129}}) {
    const Cancelled r = run_and_signal(dir_,
                                       {"extract", "field:gyroid:256", "--iso", "0", "--method",
                                        "macet", "--quality", "max", "-o", "out.ply"},
                                       "isotile: macet search: ", sig);
    expect_cancelled(r, code);
  }
}

// SIGTERM while the mesh is being written: the temporary file goes too.
TEST_F(CliCancel, SigtermDuringTheWriteExits143AndLeavesNothing) {
  const Cancelled r = run_and_signal(
      dir_, {"extract", "field:gyroid:384", "--iso", "0", "--ascii", "-o", "out.ply"},
      "isotile: write: 10%", SIGTERM);
  expect_cancelled(r, 143);
}

// Out of core, brick by brick (27 bricks): cancelled within the passes over the bricks.
TEST_F(CliCancel, SigintOutOfCoreExits130AndLeavesNothing) {
  const Cancelled r = run_and_signal(dir_,
                                     {"extract", "field:gyroid:384", "--iso", "0", "--method",
                                      "macet", "--memory", "64MiB", "-o", "out.ply"},
                                     "isotile: count: 1/", SIGINT);
  expect_cancelled(r, 130);
}

// Under nohup (SIGHUP ignored when it starts) a closed terminal does not end the run.
TEST_F(CliCancel, ASighupIgnoredOnEntryStaysIgnored) {
  const Cancelled r = run_and_signal(dir_,
                                     {"extract", "field:gyroid:128", "--iso", "0", "--method",
                                      "macet", "--quality", "max", "-o", "out.ply"},
                                     "isotile: macet search: ", SIGHUP, SIGHUP);
  ASSERT_TRUE(WIFEXITED(r.status)) << "ended by signal " << WTERMSIG(r.status) << ":\n" << r.err;
  EXPECT_EQ(WEXITSTATUS(r.status), 0) << r.err;
  EXPECT_EQ(r.left, std::vector<std::string>{"out.ply"});
}

// A run blocked reading its input (a FIFO nobody writes: open() waits for a writer) never reaches
// its next unit of work, and the call is restarted after the handler: one SIGTERM (what timeout(1)
// and batch schedulers send) still ends it, a few seconds later, leaving nothing.
TEST_F(CliCancel, OneSigtermEndsARunBlockedOnItsInput) {
  const fs::path in = dir_.parent_path() / (dir_.filename().string() + "-in");
  fs::create_directories(in);
  const fs::path fifo = in / "blocked_32x32x32_uint8.raw";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const Cancelled r = run_and_signal(
      dir_, {"extract", fifo.string(), "--iso", "100", "-o", "out.ply"}, "", SIGTERM);
  fs::remove_all(in);
  expect_cancelled(r, 143);
  EXPECT_LT(r.seconds, 30) << "ended by the test's own SIGKILL?";
}

// Other signals whose default action ends the process (a soft CPU-time limit's SIGXCPU, the user
// and timer signals) left the hidden temporary behind; they end it as before, without it.
TEST_F(CliCancel, EndingSignalsLeaveNoTemporary) {
  for (const int sig : {SIGXCPU, SIGUSR1, SIGALRM}) {
    const Cancelled r = run_and_signal(
        dir_, {"extract", "field:gyroid:384", "--iso", "0", "--ascii", "-o", "out.ply"},
        "isotile: write: 10%", sig);
    ASSERT_TRUE(WIFSIGNALED(r.status)) << sig << ": status " << r.status << ":\n" << r.err;
    EXPECT_EQ(WTERMSIG(r.status), sig);
    EXPECT_TRUE(r.left.empty()) << sig << ": left behind: " << r.left.front();
  }
}

// A crash (here a SIGSEGV sent as the kernel would send it) removes the temporaries and says so in
// one line before the default action. Sanitizer builds keep their own report instead.
TEST_F(CliCancel, ACrashLeavesNoTemporaryAndSaysSo) {
#ifdef ISOTILE_SANITIZED
  GTEST_SKIP() << "a sanitizer build reports crashes itself: isotile installs no handler there";
#else
  const Cancelled r = run_and_signal(
      dir_, {"extract", "field:gyroid:384", "--iso", "0", "--ascii", "-o", "out.ply"},
      "isotile: write: 10%", SIGSEGV);
  ASSERT_TRUE(WIFSIGNALED(r.status)) << "status " << r.status << ":\n" << r.err;
  EXPECT_EQ(WTERMSIG(r.status), SIGSEGV);
  EXPECT_NE(r.err.find("isotile: error: crashed (signal 11); its unfinished files were removed\n"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(r.left.empty()) << "left behind: " << r.left.front();
#endif
}

// stderr piped into a reader that stops (`2>&1 | head`): the progress line that meets the closed
// pipe ends the process by SIGPIPE, and the temporary goes with it.
TEST_F(CliCancel, SigpipeOnStderrLeavesNoTemporary) {
  const Cancelled r = run_and_signal(
      dir_, {"extract", "field:gyroid:384", "--iso", "0", "--ascii", "-o", "out.ply"},
      "isotile: write: 10%", SIGPIPE);
  ASSERT_TRUE(WIFSIGNALED(r.status)) << "status " << r.status << ":\n" << r.err;
  EXPECT_EQ(WTERMSIG(r.status), SIGPIPE);
  EXPECT_TRUE(r.left.empty()) << "left behind: " << r.left.front();
}

}  // namespace
