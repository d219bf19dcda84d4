// Outputs and arguments of the isotile command line: what -o and --stats do with special files
// (devices, FIFOs, sockets, links) made for each test in its own folder, paths and values that
// fail before any input is read, standard output's write errors, the empty mesh, --iso auto.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "cli_support.h"
#include "core/mesh/mesh_io.h"
#include "core/volume/itk_reader.h"
#include "test_support.h"

namespace fs = std::filesystem;

namespace {

using isotile::testing::CliResult;
using isotile::testing::slurp;

class CliOutputs : public isotile::testing::CliTest {
 protected:
  // A character device node in the work folder (1,3: a private /dev/null; 1,7: /dev/full).
  // Needs CAP_MKNOD and a folder on a file system that allows devices: skipped otherwise.
  bool make_device(const std::string& name, unsigned minor) {
    const fs::path p = dir_ / name;
    if (::mknod(p.c_str(), S_IFCHR | 0666, makedev(1, minor)) != 0) return false;
    const int fd = ::open(p.c_str(), O_WRONLY);
    if (fd < 0) {  // a file system mounted nodev
      fs::remove(p);
      return false;
    }
    ::close(fd);
    return true;
  }
#define REQUIRE_DEVICE(name, minor)                                                 \
  do {                                                                              \
    if (!make_device(name, minor))                                                  \
      GTEST_SKIP() << "cannot make a character device here (needs root and a file " \
                      "system without nodev): "                                     \
                   << std::strerror(errno);                                         \
  } while (0)

  bool is_char_device(const std::string& name) {
    struct stat st {};
    return ::lstat((dir_ / name).c_str(), &st) == 0 && S_ISCHR(st.st_mode);
  }

  // `sh -c` in the work folder, with ISOTILE for the program; stderr captured, stdout as the
  // command redirects it.
  CliResult shell(const std::string& command) {
    const std::string cmd =
        "cd '" + dir_.string() + "' && ISOTILE='" + ISOTILE_CLI + "'; " + command + " 2>stderr.txt";
    const int status = std::system(cmd.c_str());
    CliResult r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.err = slurp(dir_ / "stderr.txt");
    fs::remove(dir_ / "stderr.txt");
    return r;
  }
};

nlohmann::json json_of(const fs::path& p) {
  return nlohmann::json::parse(slurp(p));
}

bool says(const CliResult& r, const std::string& what) {
  return r.err.find("isotile: error: ") != std::string::npos &&
         r.err.find(what) != std::string::npos;
}

TEST_F(CliOutputs, AStatsDeviceIsWrittenInPlaceAndStaysADevice) {
  REQUIRE_DEVICE("null", 3);
  const CliResult r = run("extract field:sphere:16 -o s.ply -q --stats null");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(is_char_device("null"));
  EXPECT_EQ(stray_files({"null", "s.ply"}), std::vector<std::string>{});
}

TEST_F(CliOutputs, AMeshDeviceIsWrittenInPlaceInCoreAndRefusedOutOfCore) {
  REQUIRE_DEVICE("null.ply", 3);
  CliResult r = run("extract field:sphere:16 -o null.ply -q");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(is_char_device("null.ply"));
  // The streamed writer places records at offsets: refused before any brick is read.
  r = run("extract field:sphere:16 -o null.ply -q --memory 1MiB");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "null.ply: this writer places records out of order")) << r.err;
  EXPECT_TRUE(is_char_device("null.ply"));
  // The simplifying streamed writer writes front to back: a device takes it.
  r = run("extract field:sphere:24 -o null.ply -q --memory 1MiB --simplify 0.5");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(is_char_device("null.ply"));
  // Its scratch files then go to TMPDIR: one that is missing is named (it was std::filesystem's
  // "temp_directory_path: No such file or directory").
  r = run("extract field:sphere:24 -o null.ply -q --memory 1MiB --simplify 0.5",
          "TMPDIR=/nonexistent");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "the temporary folder TMPDIR=/nonexistent: No such file or directory"))
      << r.err;
  EXPECT_EQ(stray_files({"null.ply"}), std::vector<std::string>{});
}

TEST_F(CliOutputs, AFullDeviceIsAnErrorAndStaysADevice) {
  REQUIRE_DEVICE("full", 7);
  REQUIRE_DEVICE("full.ply", 7);
  CliResult r = run("extract field:sphere:16 -o s.ply -q --stats full");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "cannot write full: No space left on device")) << r.err;
  EXPECT_TRUE(is_char_device("full"));
  // The run failed: its mesh is not written either (it was, before the stats failed).
  EXPECT_FALSE(fs::exists(dir_ / "s.ply"));
  ASSERT_EQ(run("extract field:sphere:16 -o s.ply -q").code, 0);
  r = run("extract field:sphere:16 -o full.ply -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "cannot write full.ply: No space left on device")) << r.err;
  EXPECT_TRUE(is_char_device("full.ply"));
  r = run("simplify s.ply full.ply --ratio 0.5 -q");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "cannot write full.ply")) << r.err;
  EXPECT_TRUE(is_char_device("full.ply"));
}

TEST_F(CliOutputs, StandardOutputWriteErrorsExitOne) {
  REQUIRE_DEVICE("full", 7);
  ASSERT_EQ(run("extract field:sphere:16 -o s.ply -q").code, 0);
  for (const std::string args :
       {"extract field:sphere:16 -o t.ply -q --stats -", "info field:sphere:16",
        "info field:sphere:16 --json", "quality s.ply", "quality s.ply --json",
        "simplify s.ply u.ply --ratio 0.5 -q --stats -", "demo -o d.ply -q", "--help",
        "extract --help", "--version"}) {
    const CliResult r = shell("\"$ISOTILE\" " + args + " >full");
    EXPECT_EQ(r.code, 1) << args;
    EXPECT_TRUE(says(r, "cannot write standard output: No space left on device"))
        << args << ": " << r.err;
  }
  EXPECT_TRUE(is_char_device("full"));
}

TEST_F(CliOutputs, AFifoIsWrittenInPlaceAndRefusedOutOfCoreWithoutBlocking) {
  ASSERT_EQ(::mkfifo((dir_ / "fifo").c_str(), 0644), 0) << std::strerror(errno);
  std::string got;
  std::thread reader([&] { got = slurp(dir_ / "fifo"); });
  const CliResult r = run("extract field:sphere:16 -o s.ply -q --stats fifo");
  // Had the program never opened the FIFO, the reader would wait for ever: a writer of our own
  // releases it (where the program wrote and closed it, no reader is left to open it for).
  if (const int fd = ::open((dir_ / "fifo").c_str(), O_WRONLY | O_NONBLOCK); fd >= 0) ::close(fd);
  reader.join();
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(got)["triangles"].get<int>() > 0, true);
  struct stat st {};
  ASSERT_EQ(::lstat((dir_ / "fifo").c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  // Refused before the FIFO is opened (opening it would wait for a reader).
  fs::rename(dir_ / "fifo", dir_ / "fifo.ply");
  const CliResult o = shell(
      "timeout 20 \"$ISOTILE\" extract field:sphere:16 -o fifo.ply -q "
      "--memory 1MiB");
  EXPECT_EQ(o.code, 1) << o.err;
  EXPECT_TRUE(says(o, "fifo.ply: this writer places records out of order")) << o.err;
}

TEST_F(CliOutputs, ASocketIsRefusedBeforeAnyWork) {
  const int s = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(s, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  const std::string path = (dir_ / "sock.json").string();
  ASSERT_LT(path.size(), sizeof addr.sun_path);
  std::strcpy(addr.sun_path, path.c_str());
  ASSERT_EQ(::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0) << std::strerror(errno);
  // A missing input: the output is checked first, so the error names the socket.
  const CliResult r = run("extract missing_8x8x8_uint8.raw --iso 1 -o s.ply --stats sock.json");
  ::close(s);
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "cannot write sock.json: it is a socket")) << r.err;
  EXPECT_EQ(stray_files({"sock.json"}), std::vector<std::string>{});
}

TEST_F(CliOutputs, ALinkToARegularFileKeepsTheLinkAndReplacesTheTarget) {
  fs::create_directory(dir_ / "real");
  { std::ofstream(dir_ / "real" / "s.json") << "old"; }
  { std::ofstream(dir_ / "real" / "m.ply") << "old"; }
  fs::create_symlink("real/s.json", dir_ / "s.json");
  fs::create_symlink(dir_ / "real" / "m.ply", dir_ / "m.ply");  // absolute
  fs::create_symlink("real/new.ply", dir_ / "dangling.ply");
  CliResult r = run("extract field:sphere:16 -o m.ply -q --stats s.json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir_ / "s.json"));
  EXPECT_TRUE(fs::is_symlink(dir_ / "m.ply"));
  EXPECT_GT(json_of(dir_ / "real" / "s.json")["triangles"].get<int>(), 0);
  EXPECT_GT(isotile::read_mesh(dir_ / "real" / "m.ply").triangles.size(), 0u);
  // A dangling link: the file is made where it points.
  r = run("extract field:sphere:16 -o dangling.ply -q --memory 1MiB");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir_ / "dangling.ply"));
  EXPECT_EQ(slurp(dir_ / "real" / "new.ply"), slurp(dir_ / "real" / "m.ply"));
  EXPECT_EQ(stray_files({"real", "s.json", "m.ply", "dangling.ply"}), std::vector<std::string>{});
}

// A replaced file keeps its permission bits (a private 0600 mesh did not stay private: the rename
// put a new 0644 file in its place), in core and out of core, the stats file too.
TEST_F(CliOutputs, AReplacedFileKeepsItsPermissions) {
  for (const std::string extra : {"", " --memory 1MiB"}) {
    { std::ofstream(dir_ / "m.ply") << "old"; }
    { std::ofstream(dir_ / "s.json") << "old"; }
    fs::permissions(dir_ / "m.ply", fs::perms::owner_read | fs::perms::owner_write);
    fs::permissions(dir_ / "s.json",
                    fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
    const CliResult r = run("extract field:sphere:16 -o m.ply -q --stats s.json" + extra);
    ASSERT_EQ(r.code, 0) << extra << ": " << r.err;
    EXPECT_GT(isotile::read_mesh(dir_ / "m.ply").triangles.size(), 0u) << extra;
    EXPECT_EQ(fs::status(dir_ / "m.ply").permissions(),
              fs::perms::owner_read | fs::perms::owner_write)
        << extra;
    EXPECT_EQ(fs::status(dir_ / "s.json").permissions(),
              fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read)
        << extra;
  }
  // The owner (now whoever ran isotile) keeps reading and writing it: a file writable only
  // through its group gave a file its new owner could not replace. Root may write any file.
  if (::geteuid() == 0) {
    fs::permissions(dir_ / "m.ply", fs::perms::group_read | fs::perms::group_write);
    const CliResult r = run("extract field:sphere:16 -o m.ply -q");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(fs::status(dir_ / "m.ply").permissions(),
              fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read |
                  fs::perms::group_write);
  }
}

// A file its owner made read-only is refused, as `>` would refuse it, before any work; it was
// replaced. Root may write anything, so as root the command runs as nobody (setpriv).
TEST_F(CliOutputs, AReadOnlyOutputIsRefused) {
  { std::ofstream(dir_ / "ro.ply") << "old"; }
  fs::permissions(dir_ / "ro.ply",
                  fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
  fs::permissions(dir_, fs::perms::all);  // the folder is writable: only the file is not
  const std::string as_user =
      ::geteuid() == 0 ? "setpriv --reuid=65534 --regid=65534 --clear-groups" : "";
  for (const std::string args : {"extract field:sphere:16 -o ro.ply -q",
                                 "extract field:sphere:16 -o m.ply -q --stats ro.ply",
                                 "extract field:sphere:16 -o ro.ply -q --memory 1MiB"}) {
    const CliResult r = run(args, as_user);
    EXPECT_EQ(r.code, 1) << args << ": " << r.err;
    EXPECT_EQ(r.err,
              "isotile: error: cannot write ro.ply: the file is not writable (Permission "
              "denied)\n")
        << args;
    EXPECT_EQ(slurp(dir_ / "ro.ply"), "old") << args;
    EXPECT_EQ(stray_files({"ro.ply"}), std::vector<std::string>{}) << args;
  }
}

TEST_F(CliOutputs, ADescriptorLinkAppendsToTheRedirectedLog) {
  // Links of our own into /proc/self/fd, as /dev/stdout is.
  fs::create_symlink("/proc/self/fd/1", dir_ / "out.json");
  fs::create_symlink("out.json", dir_ / "chained.json");
  { std::ofstream(dir_ / "log") << "first line\n"; }
  CliResult r = shell("\"$ISOTILE\" extract field:sphere:16 -o s.ply -q --stats out.json >>log");
  ASSERT_EQ(r.code, 0) << r.err;
  r = shell("\"$ISOTILE\" extract field:sphere:16 -o s.ply -q --stats chained.json >>log");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir_ / "out.json"));
  const std::string log = slurp(dir_ / "log");
  EXPECT_EQ(log.rfind("first line\n{", 0), 0u) << log;
  const std::string one = log.substr(std::string("first line\n").size());
  // Two JSON objects, one after the other.
  const std::size_t split = one.find("}\n{");
  ASSERT_NE(split, std::string::npos) << log;
  const std::string a = one.substr(0, split + 2), b = one.substr(split + 2);
  EXPECT_GT(nlohmann::json::parse(a)["triangles"].get<int>(), 0);
  EXPECT_EQ(nlohmann::json::parse(a)["triangles"], nlohmann::json::parse(b)["triangles"]);
  // The descriptor is whatever it holds: a pipe too.
  r = shell("\"$ISOTILE\" extract field:sphere:16 -o s.ply -q --stats out.json | cat >piped");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_GT(json_of(dir_ / "piped")["triangles"].get<int>(), 0);
  // The simplifying streamed writer goes front to back, so it takes standard output too; its
  // scratch files go to TMPDIR, not into /proc/self/fd.
  fs::create_directory(dir_ / "tmp");
  fs::create_symlink("/proc/self/fd/1", dir_ / "mesh.ply");
  r = shell(
      "TMPDIR=\"$PWD/tmp\" \"$ISOTILE\" extract field:sphere:24 -o mesh.ply -q "
      "--memory 1MiB --simplify 0.5 >streamed.ply");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_GT(isotile::read_mesh(dir_ / "streamed.ply").triangles.size(), 100u);
  EXPECT_TRUE(fs::is_empty(dir_ / "tmp"));
  // A descriptor that is not open: refused before any work.
  fs::create_symlink("/proc/self/fd/9", dir_ / "nine.json");
  r = shell(
      "\"$ISOTILE\" extract missing_8x8x8_uint8.raw --iso 1 -o s.ply -q "
      "--stats nine.json 9>&-");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "cannot write nine.json: descriptor 9 is closed")) << r.err;
}

TEST_F(CliOutputs, BadOutputPathsFailBeforeTheInputIsRead) {
  fs::create_directory(dir_ / "adir.ply");
  struct Bad {
    std::string args, says;
  } const cases[] = {
      {"-o nope/out.ply", "cannot write nope/out.ply: folder nope does not exist"},
      {"-o adir.ply", "cannot write adir.ply: it is a directory"},
      {"-o out.xyz", "unknown mesh format '.xyz'"},
      {"-o out", "no extension"},
      {"-o out.ply --stats nope/s.json", "cannot write nope/s.json: folder nope does not exist"},
      {"-o out.ply --stats adir.ply", "cannot write adir.ply: it is a directory"},
      {"-o out.ply --spacing 1,0,1", "--spacing"},
  };
  for (const Bad& b : cases) {
    // The input does not exist: had it been read first, the error would name it.
    const CliResult r = run("extract missing_8x8x8_uint8.raw --iso 1 " + b.args);
    EXPECT_EQ(r.code, 1) << b.args;
    EXPECT_TRUE(says(r, b.says)) << b.args << ": " << r.err;
    EXPECT_EQ(r.err.find("missing_8x8x8"), std::string::npos) << b.args << ": " << r.err;
  }
  const CliResult s = run("simplify missing.ply nope/out.ply --ratio 0.5");
  EXPECT_EQ(s.code, 1);
  EXPECT_TRUE(says(s, "folder nope does not exist")) << s.err;
  const CliResult t = run("simplify missing.ply out.ply --ratio 0.5 --stats adir.ply");
  EXPECT_EQ(t.code, 1);
  EXPECT_TRUE(says(t, "it is a directory")) << t.err;
  EXPECT_EQ(stray_files({"adir.ply"}), std::vector<std::string>{});
}

// Options that would be dropped without a word are errors: an empty value (an unset shell
// variable: --memory "" ran in core), a method's option with another method, --ascii for STL.
TEST_F(CliOutputs, OptionsThatWouldBeDroppedAreErrors) {
  struct Bad {
    std::string args, says;
    int code;
  } const cases[] = {
      {"--memory ''", "--memory: must not be empty", 2},
      {"--stats ''", "--stats: must not be empty", 2},
      {"--iso ''", "--iso: must not be empty", 2},
      {"--spacing ''", "--spacing: must not be empty", 2},
      {"--method mc --quads", "--quads applies to --method dc only", 1},
      {"--method macet --dc-solver qef", "--dc-solver applies to --method dc only", 1},
      {"--dc-vertices cell", "--dc-vertices applies to --method dc only", 1},
      {"--method dc --quality max", "--quality applies to --method macet only", 1},
      {"--ascii", "--ascii writes PLY as text; STL is written binary only", 1},
      // STL's writer would cut the quads on a fixed diagonal: worse than the stats said.
      {"--method dc --quads", "STL holds triangles only: drop --quads", 1},
      {"--method dc --quads --memory 1MiB", "STL holds triangles only: drop --quads", 1},
  };
  for (const Bad& b : cases) {
    const bool stl = b.args == "--ascii" || b.args.rfind("--method dc --quads", 0) == 0;
    const std::string out = stl ? "out.stl" : "out.ply";
    const CliResult r = run("extract field:sphere:16 -o " + out + " " + b.args);
    EXPECT_EQ(r.code, b.code) << b.args << ": " << r.err;
    EXPECT_NE(r.err.find(b.says), std::string::npos) << b.args << ": " << r.err;
    EXPECT_EQ(stray_files(), std::vector<std::string>{}) << b.args;
  }
  // simplify's --stats too (it wrote no stats, exit 0).
  ASSERT_EQ(run("extract field:sphere:12 -q -o in.ply").code, 0);
  const CliResult r = run("simplify in.ply s.ply --ratio 0.5 --stats ''");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--stats: must not be empty"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "s.ply"));
  fs::remove(dir_ / "in.ply");
  // With their own method they run.
  for (const std::string ok :
       {"--method dc --quads --dc-solver qef", "--method macet --quality max"})
    EXPECT_EQ(run("extract field:sphere:12 -q -o ok.ply " + ok).code, 0) << ok;
}

// Two of a run's files that are one file: refused before any work, the files as they were (the
// stats used to replace the mesh, or the input volume, with exit 0).
TEST_F(CliOutputs, AnOutputThatIsAnotherOutputOrTheInputIsRefused) {
  ASSERT_EQ(run("extract field:sphere:16 -q -o m.ply").code, 0);
  const std::string mesh = slurp(dir_ / "m.ply");
  std::ofstream(dir_ / "v_8x8x8_uint8.raw", std::ios::binary) << std::string(512, '\x10');
  fs::create_directory(dir_ / "sub");
  struct Bad {
    std::string args, says;
  } const cases[] = {
      {"extract field:sphere:16 -o m.ply --stats m.ply",
       "--stats m.ply is the same file as the output"},
      {"extract field:sphere:16 -o m.ply --stats sub/../m.ply", "the same file as the output"},
      {"extract field:sphere:16 -o m.ply --memory 1MiB --stats ./m.ply", "the same file"},
      {"extract v_8x8x8_uint8.raw --iso 9 -o out.ply --stats v_8x8x8_uint8.raw",
       "--stats v_8x8x8_uint8.raw is the same file as the input"},
      {"simplify m.ply out.ply --ratio 0.5 --stats m.ply", "the same file as the input"},
      {"simplify m.ply m.ply --ratio 0.5", "the output m.ply is the same file as the input"},
      {"simplify m.ply out.ply --ratio 0.5 --stats out.ply", "the same file as the output"},
      // Neither there yet, spelled two ways (the stats replaced the mesh, exit 0), or one a
      // dangling link to the other.
      {"extract field:sphere:16 -o ./out.ply --stats out.ply", "the same file as the output"},
      {"extract field:sphere:16 -o out.ply --stats " + (dir_ / "out.ply").string(),
       "the same file as the output"},
      {"extract field:sphere:16 -o out.ply --stats sub/../out.ply", "the same file as the output"},
      {"simplify m.ply ./out.ply --ratio 0.5 --stats out.ply", "the same file as the output"},
      {"extract field:sphere:16 -o out.ply --render to_out.png", "the same file as the output"},
      {"extract field:sphere:16 -o out.ply --stats to_out.json", "the same file as the output"},
  };
  fs::create_symlink("out.ply", dir_ / "to_out.png");
  fs::create_symlink("out.ply", dir_ / "to_out.json");
  for (const Bad& b : cases) {
    const CliResult r = run(b.args);
    EXPECT_EQ(r.code, 1) << b.args;
    EXPECT_TRUE(says(r, b.says)) << b.args << ": " << r.err;
    EXPECT_EQ(slurp(dir_ / "m.ply"), mesh) << b.args;
    EXPECT_EQ(fs::file_size(dir_ / "v_8x8x8_uint8.raw"), 512u) << b.args;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << b.args;
  }
}

// "-" is standard output, which the shell may point at an output (`--stats - > m.ply`): the
// stats and the mesh would share one file (exit 0 before, the mesh replacing the stats).
TEST_F(CliOutputs, StatsOnAStandardOutputThatIsTheOutputAreRefused) {
  for (const std::string& cmd :
       {std::string("extract field:sphere:12 -o m.ply --stats - >m.ply"),
        std::string("extract field:sphere:12 -o m.ply --stats - >>m.ply")}) {
    const CliResult r = shell("\"$ISOTILE\" -q " + cmd);
    EXPECT_EQ(r.code, 1) << cmd;
    EXPECT_TRUE(says(r, "- is the same file as the output")) << cmd << ": " << r.err;
  }
  // demo has no --stats to name.
  const CliResult demo = shell("\"$ISOTILE\" -q demo >isotile-demo.ply");
  EXPECT_EQ(demo.code, 1);
  EXPECT_TRUE(says(demo,
                   "standard output, where demo prints its statistics, is the output "
                   "isotile-demo.ply (one would replace the other)"))
      << demo.err;
  // Standard output a pipe and the output a link to it: std::filesystem::equivalent took a pipe
  // for no file, and the mesh and the stats went down the pipe together, exit 0.
  fs::create_symlink("/dev/stdout", dir_ / "out.ply");
  for (const auto& [cmd, error] : {std::pair{"extract field:sphere:12 -o out.ply --stats -",
                                             "- is the same file as the output"},
                                   std::pair{"demo -o out.ply", "is the output out.ply"}}) {
    shell("\"$ISOTILE\" -q " + std::string(cmd) + " 2>err.txt | cat >piped.bin");
    const std::string err = slurp(dir_ / "err.txt");
    EXPECT_NE(err.find(error), std::string::npos) << cmd << ": " << err;
    EXPECT_EQ(fs::file_size(dir_ / "piped.bin"), 0u) << cmd;
  }
  // /dev/null takes any number of writers.
  fs::create_symlink("/dev/null", dir_ / "null.ply");
  const CliResult null = run("extract field:sphere:12 -q -o null.ply --stats /dev/null");
  EXPECT_EQ(null.code, 0) << null.err;
  // Elsewhere it is written there.
  const CliResult r = shell("\"$ISOTILE\" -q extract field:sphere:12 -o m.ply --stats - >s.json");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_GT(json_of(dir_ / "s.json")["triangles"].get<int>(), 0);
}

// The stats' "threads" is what ran: --threads, or the cores where there are fewer (it said the
// limit asked for); a count TBB cannot reserve is a usage error, not "out of memory".
// A closed stderr (`2>&-`): the output's temporary took descriptor 2, and the progress lines went
// into the mesh, exit 0; out of core they overwrote records in the middle. The same bytes as
// with stderr open, in core, out of core and simplified; a closed stdout still fails `--stats -`.
TEST_F(CliOutputs, ClosedStandardDescriptorsTakeNoOutput) {
  for (const std::string& args : {std::string("extract field:gyroid:24 -o m.ply"),
                                  std::string("extract field:gyroid:24 -o m.ply --memory 64KiB"),
                                  std::string("extract field:gyroid:24 -o m.ply --simplify 0.5"),
                                  std::string("demo -o m.ply >/dev/null")}) {
    ASSERT_EQ(shell("\"$ISOTILE\" " + args + " 2>/dev/null").code, 0) << args;
    const std::string open = slurp(dir_ / "m.ply");
    fs::remove(dir_ / "m.ply");
    // In braces: shell() sends the command's stderr to a file after it.
    EXPECT_EQ(shell("{ \"$ISOTILE\" " + args + " 2>&-; }").code, 0) << args;
    EXPECT_EQ(slurp(dir_ / "m.ply"), open) << args;
  }
  // The stats failing after the mesh was written: the old mesh stays (the new one had replaced it
  // before the stats were written, exit 1), and no temporary is left.
  std::ofstream(dir_ / "s.ply") << "old";
  const CliResult r = shell("{ \"$ISOTILE\" -q extract field:gyroid:24 -o s.ply --stats - >&-; }");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "standard output")) << r.err;
  EXPECT_EQ(slurp(dir_ / "s.ply"), "old");
  EXPECT_EQ(stray_files({"m.ply", "s.ply", "stderr.txt"}), std::vector<std::string>{});
}

TEST_F(CliOutputs, TheStatsSayTheThreadsThatRan) {
  const auto cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  for (const int asked : {1, 64}) {
    const CliResult r = run("-q --threads " + std::to_string(asked) +
                            " extract field:sphere:16 -o t.ply --stats -");
    ASSERT_EQ(r.code, 0) << r.err;
    const int ran = nlohmann::json::parse(r.out)["threads"].get<int>();
    EXPECT_GE(ran, 1) << asked;
    EXPECT_LE(ran, std::min(asked, cores)) << asked;
  }
  const CliResult r = run("--threads 1000000000 extract field:sphere:16 -o t.ply");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--threads"), std::string::npos) << r.err;
}

// Raw samples from a pipe are read once, in order, in core (looking at the input's first bytes
// for its format consumed them, so the samples came up short); out of core, which reads its input
// twice, a pipe is refused saying so.
TEST_F(CliOutputs, RawSamplesFromAPipeAreReadInCoreAndRefusedOutOfCore) {
  std::string ball(16 * 16 * 16, '\0');
  for (int k = 0; k < 16; ++k)
    for (int j = 0; j < 16; ++j)
      for (int i = 0; i < 16; ++i)
        ball[static_cast<std::size_t>((k * 16 + j) * 16 + i)] = static_cast<char>(
            (i - 7) * (i - 7) + (j - 8) * (j - 8) + (k - 7) * (k - 7) < 30 ? 200 : 10);
  std::ofstream(dir_ / "v_16x16x16_uint8.raw", std::ios::binary) << ball;
  ASSERT_EQ(run("-q extract v_16x16x16_uint8.raw --iso 100 -o file.ply").code, 0);
  const std::string raw = " -q extract /dev/stdin --dims 16,16,16 --type uint8 --iso 100";
  CliResult r = shell("cat v_16x16x16_uint8.raw | \"$ISOTILE\"" + raw + " -o pipe.ply");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(slurp(dir_ / "pipe.ply"), slurp(dir_ / "file.ply"));
  r = shell("cat v_16x16x16_uint8.raw | \"$ISOTILE\"" + raw + " -o ooc.ply --memory 1MiB");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "a pipe or device, which can be read only once")) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "ooc.ply"));
}

// A legal name of 250 bytes: the temporary file beside it must fit NAME_MAX (255) too.
TEST_F(CliOutputs, ALongLegalOutputNameIsWritten) {
  const std::string name = std::string(246, 'a') + ".ply";
  const CliResult r = run("extract field:sphere:16 -q -o " + name);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_GT(isotile::read_mesh(dir_ / name).triangles.size(), 100u);
  EXPECT_EQ(stray_files({name}), std::vector<std::string>{});
}

TEST_F(CliOutputs, BadNumbersAreOneLineErrors) {
  struct Bad {
    std::string args, says;
  } const cases[] = {
      {"--spacing 0,1,1", "--spacing must be three finite numbers above 0, got '0,1,1'"},
      {"--spacing -1,1,1", "--spacing must be three finite numbers above 0"},
      {"--spacing nan,1,1", "--spacing must be three finite numbers above 0"},
      {"--spacing 1,inf,1", "--spacing must be three finite numbers above 0"},
      {"--origin 0,nan,0", "--origin must be three finite numbers"},
      {"--origin 0,0,-inf", "--origin must be three finite numbers"},
      {"--iso nan", "--iso must be a finite number or 'auto', got 'nan'"},
      {"--iso inf", "--iso must be a finite number or 'auto'"},
      {"--iso 1x", "--iso must be a finite number or 'auto', got '1x'"},
      // Blanks before it were passed over (strtod's), after it refused: refused either way.
      {"--iso ' 0.25'", "--iso must be a finite number or 'auto', got ' 0.25'"},
      {"--iso '0.25 '", "--iso must be a finite number or 'auto', got '0.25 '"},
      // A fourth value, or a trailing comma, was dropped without a word.
      {"--spacing 1,1,1,7", "--spacing must be three comma-separated numbers, got '1,1,1,7'"},
      {"--origin 1,2,3,", "--origin must be three comma-separated numbers"},
      {"--spacing 1,,1", "--spacing must be three comma-separated numbers"},
      {"--dims 16,16,16,2 --type float32", "--dims must be three comma-separated numbers"},
  };
  for (const Bad& b : cases) {
    const CliResult r = run("extract field:sphere:16 -o out.ply " + b.args);
    EXPECT_EQ(r.code, 1) << b.args;
    EXPECT_TRUE(says(r, b.says)) << b.args << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << b.args;
  }
}

// A 4x4x4 uint8 NRRD of constant samples whose header has `geometry` (its spacing, space and
// origin lines) besides the fields every one has.
void write_geometry_nrrd(const fs::path& path, const std::string& geometry) {
  std::ofstream(path, std::ios::binary) << "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 4 4 4\n"
                                        << geometry << "encoding: raw\n\n"
                                        << std::string(64, '\x10');
}

TEST_F(CliOutputs, BadGeometryInAFileIsAnError) {
  write_geometry_nrrd(dir_ / "singular.nrrd",
                      "space: left-posterior-superior\nspace directions: (1,0,0) (1,0,0) "
                      "(0,0,1)\nspace origin: (0,0,0)\n");
  write_geometry_nrrd(dir_ / "flipped.nrrd", "spacings: -1 1 1\n");
  for (const std::string memory : {"", " --memory 1MiB"}) {
    CliResult r = run("extract singular.nrrd --iso 1 -o out.ply" + memory);
    EXPECT_EQ(r.code, 1);
    EXPECT_TRUE(says(r, "singular.nrrd: the direction matrix is singular")) << r.err;
    r = run("extract flipped.nrrd --iso 1 -o out.ply" + memory);
    EXPECT_EQ(r.code, 1);
    EXPECT_TRUE(says(r, "flipped.nrrd: the spacing must be finite and positive")) << r.err;
    // --spacing overrides the file's.
    r = run("extract flipped.nrrd --iso 1 -o out.ply --spacing 1,1,1 --allow-empty -q" + memory);
    EXPECT_EQ(r.code, 0) << r.err;
  }
  // info refuses what extract refuses, with the same line (it said such a file was fine).
  write_geometry_nrrd(dir_ / "huge.nrrd", "spacings: 2e38 1 1\n");
  for (const auto& [file, message] :
       {std::pair{"singular.nrrd", "singular.nrrd: the direction matrix is singular"},
        std::pair{"flipped.nrrd", "flipped.nrrd: the spacing must be finite and positive"},
        std::pair{"huge.nrrd", "huge.nrrd: the grid's coordinates reach 6e+38"}}) {
    const CliResult r = run(std::string("info ") + file);
    EXPECT_EQ(r.code, 1) << file;
    EXPECT_TRUE(says(r, message)) << r.err;
    EXPECT_EQ(r.out, "") << file;
  }
  EXPECT_EQ(run("info flipped.nrrd --spacing 1,1,1").code, 0);
}

// Positions are written as float32: a file whose grid passes float32's range is refused (its
// vertices would be inf), as is a grid whose cells are narrower than a float32 step (they would
// collapse); one whose vertices would snap to a coarse lattice (UTM-like coordinates) is said,
// once, in core, out of core and under --frame grid, and the run goes on.
TEST_F(CliOutputs, PositionsFloat32CannotHoldAreRefusedAndCoarseOnesSaid) {
  write_geometry_nrrd(dir_ / "huge.nrrd", "spacings: 2e38 1 1\n");
  for (const std::string memory : {"", " --memory 1MiB"}) {
    CliResult r = run("extract huge.nrrd --iso 1 --allow-empty -o out.ply" + memory);
    EXPECT_EQ(r.code, 1) << memory;
    EXPECT_TRUE(says(r,
                     "huge.nrrd: the grid's coordinates reach 6e+38, beyond the largest "
                     "float32 (3.40282e+38), in which positions are written"))
        << r.err;
    r = run("extract field:sphere:16 -o out.ply --origin 1,0,0 --spacing 1e-9,1,1" + memory);
    EXPECT_EQ(r.code, 1) << memory;
    EXPECT_TRUE(says(r, "the grid's cells, 1e-09 wide, are narrower than a float32 step")) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.ply")) << memory;
    for (const std::string frame : {"", " --frame grid"}) {
      r = run("extract field:sphere:16 -q -o out.ply --origin 5e6,5e6,0" + memory + frame);
      EXPECT_EQ(r.code, 0) << memory << frame << r.err;
      EXPECT_EQ(r.err,
                "isotile: warning: positions are float32: at the grid's coordinates of up to "
                "5.00002e+06 a float32 steps by 0.5, against cells 1 wide, so vertices snap to a "
                "lattice of about 2 steps per cell, which makes thin and degenerate triangles; a "
                "grid nearer 0 (the CLI's --origin) keeps full precision\n")
          << memory << frame;
      EXPECT_TRUE(fs::exists(dir_ / "out.ply"));
      fs::remove(dir_ / "out.ply");
    }
    r = run("extract field:sphere:16 -q -o out.ply --origin 5e5,5e5,0" + memory);
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err, "") << memory;
    fs::remove(dir_ / "out.ply");
  }
}

// --spacing and --origin place a procedural field's grid in core as out of core: the same file
// (in core they were ignored, so the two differed).
TEST_F(CliOutputs, AFieldTakesSpacingAndOriginInCoreAsOutOfCore) {
  ASSERT_EQ(run("extract field:sphere:16 -q -o a.ply --origin 3,2,1 --spacing 0.5,1,2").code, 0);
  ASSERT_EQ(run("extract field:sphere:16 -q -o b.ply --origin 3,2,1 --spacing 0.5,1,2 --memory "
                "1MiB")
                .code,
            0);
  EXPECT_EQ(slurp(dir_ / "a.ply"), slurp(dir_ / "b.ply"));
  ASSERT_EQ(run("extract field:sphere:16 -q -o c.ply").code, 0);
  EXPECT_NE(slurp(dir_ / "a.ply"), slurp(dir_ / "c.ply"));
}

TEST_F(CliOutputs, AnIsovalueOutsideTheSamplesIsAnErrorNamingTheRange) {
  for (const std::string memory : {"", " --memory 1MiB", " --memory 1MiB --simplify 0.5"}) {
    CliResult r = run("extract field:sphere:16 --iso 5 -o out.ply" + memory);
    EXPECT_EQ(r.code, 1) << memory;
    EXPECT_TRUE(says(r, "no surface at iso 5: the samples range from ")) << memory << r.err;
    EXPECT_NE(r.err.find(", all below it"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("--allow-empty"), std::string::npos) << r.err;
    EXPECT_EQ(stray_files(), std::vector<std::string>{}) << memory;
    r = run("extract field:sphere:16 --iso -5 -o out.ply" + memory);
    EXPECT_EQ(r.code, 1) << memory;
    EXPECT_NE(r.err.find(", all at or above it"), std::string::npos) << r.err;

    r = run("extract field:sphere:16 --iso 5 --allow-empty -q -o out.ply --stats s.json" + memory);
    ASSERT_EQ(r.code, 0) << memory << r.err;
    EXPECT_EQ(isotile::read_mesh(dir_ / "out.ply").triangles.size(), 0u);
    const auto j = json_of(dir_ / "s.json");
    EXPECT_EQ(j["triangles"], 0);
    for (const char* key : {"closed", "watertight", "radius_ratio_min", "radius_ratio_mean",
                            "radius_ratio_median", "radius_ratio_q001", "radius_ratio_q01"})
      EXPECT_TRUE(j.contains(key) && j[key].is_null()) << key << memory << ": " << j.dump();
    fs::remove(dir_ / "out.ply");
    fs::remove(dir_ / "s.json");
  }
}

// No face although samples straddle the isovalue: a volume one sample thick (no cells), or DC on
// a surface that meets only the volume's border. The same error in core and out of core, saying
// so; --allow-empty writes the empty mesh in both.
TEST_F(CliOutputs, NoFaceIsAnErrorInCoreAsOutOfCoreEvenInsideTheRange) {
  {
    std::ofstream flat(dir_ / "flat_16x16x1_float32.raw", std::ios::binary);
    for (int i = 0; i < 256; ++i) {
      const float v = static_cast<float>(i) / 255.0f;
      flat.write(reinterpret_cast<const char*>(&v), sizeof v);
    }
    std::string corner(8 * 8 * 8, '\0');
    corner[0] = '\xff';
    std::ofstream(dir_ / "corner_8x8x8_uint8.raw", std::ios::binary) << corner;
  }
  for (const std::string input :
       {"flat_16x16x1_float32.raw --iso 0.5", "corner_8x8x8_uint8.raw --iso 100 --method dc"})
    for (const std::string memory : {"", " --memory 1MiB", " --memory 1MiB --simplify 0.5"}) {
      if (input.find("dc") != std::string::npos && memory.find("simplify") != std::string::npos)
        continue;  // (the simplifying tiler needs triangles)
      CliResult r = run("extract " + input + " -o out.ply" + memory);
      EXPECT_EQ(r.code, 1) << input << memory;
      EXPECT_TRUE(says(r, "but no face crosses it")) << input << memory << ": " << r.err;
      EXPECT_EQ(r.err.find("all at or above"), std::string::npos) << r.err;
      EXPECT_EQ(stray_files({"flat_16x16x1_float32.raw", "corner_8x8x8_uint8.raw"}),
                std::vector<std::string>{})
          << input << memory;
      r = run("extract " + input + " -o out.ply --allow-empty -q" + memory);
      EXPECT_EQ(r.code, 0) << input << memory << ": " << r.err;
      fs::remove(dir_ / "out.ply");
    }
}

TEST_F(CliOutputs, AnEmptyMeshFileMeasuresAsNull) {
  ASSERT_EQ(run("extract field:sphere:16 --iso 5 --allow-empty -q -o e.ply").code, 0);
  const CliResult r = run("quality e.ply --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  for (const char* key : {"closed", "watertight", "radius_ratio_min", "radius_ratio_q01"})
    EXPECT_TRUE(j[key].is_null()) << key;
  const std::string text = run("quality e.ply").out;
  EXPECT_NE(text.find("closed                n/a"), std::string::npos) << text;
  EXPECT_NE(text.find("radius ratio          n/a (no triangles)"), std::string::npos) << text;
}

TEST_F(CliOutputs, IsoAutoFindsASurfaceInEveryField) {
  for (const char* field : {"sphere", "torus", "gyroid", "csg-box", "marschner-lobb"}) {
    const std::string in = std::string("field:") + field + ":24";
    const CliResult r = run("extract " + in + " --iso auto -o a.ply --stats a.json");
    ASSERT_EQ(r.code, 0) << field << r.err;
    EXPECT_NE(r.err.find("--iso auto: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("(Otsu's threshold; the samples range from "), std::string::npos);
    const auto j = json_of(dir_ / "a.json");
    EXPECT_GT(j["triangles"].get<int>(), 100) << field;
    EXPECT_EQ(j["iso_auto"]["rule"], "otsu");
    EXPECT_LT(j["iso_auto"]["min"].get<double>(), j["iso"].get<double>());
    EXPECT_GT(j["iso_auto"]["max"].get<double>(), j["iso"].get<double>());
    // The printed value is the one that ran, to the last bit (ten digits printed 1 for
    // 1.0000000000753726), in extract's line and info's.
    const auto printed = [](const std::string& text, const std::string& after) {
      const std::size_t at = text.find(after);
      return at == std::string::npos ? -1.0
                                     : std::strtod(text.c_str() + at + after.size(), nullptr);
    };
    EXPECT_EQ(printed(r.err, "--iso auto: "), j["iso"].get<double>()) << r.err;
    const CliResult info_text = run("info " + in);
    EXPECT_EQ(printed(info_text.out, "iso auto "), j["iso"].get<double>()) << info_text.out;
    // `info` names the same value.
    const CliResult info = run("info " + in + " --json");
    ASSERT_EQ(info.code, 0) << info.err;
    EXPECT_EQ(nlohmann::json::parse(info.out)["iso_auto"], j["iso"]) << field;
    // Out of core: the same isovalue from a streamed histogram, so the same file.
    const CliResult m =
        run("extract " + in + " --iso auto -q -o m.ply --stats m.json --memory 1MiB");
    ASSERT_EQ(m.code, 0) << field << m.err;
    EXPECT_EQ(json_of(dir_ / "m.json")["iso"], j["iso"]) << field;
    EXPECT_EQ(slurp(dir_ / "m.ply"), slurp(dir_ / "a.ply")) << field;
  }
}

TEST_F(CliOutputs, AConstantVolumeHasNoAutomaticIsovalue) {
  { std::ofstream(dir_ / "flat_4x4x4_uint8.raw", std::ios::binary) << std::string(64, '\x07'); }
  const CliResult r = run("extract flat_4x4x4_uint8.raw --iso auto -o out.ply");
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(says(r, "every sample is 7: no isovalue separates an inside from an outside"))
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "out.ply"));
  const CliResult info = run("info flat_4x4x4_uint8.raw --json");
  ASSERT_EQ(info.code, 0) << info.err;
  EXPECT_TRUE(nlohmann::json::parse(info.out)["iso_auto"].is_null());
}

TEST_F(CliOutputs, IsoAutoFindsASurfaceInEverySharedVolume) {
  const fs::path data = isotile::testing::shared_volume("");
  ISOTILE_REQUIRE_SHARED(data);
  int volumes = 0;
  for (const auto& e : fs::directory_iterator(data)) {
    const std::string name = e.path().filename().string();
    if (name.find(".raw") == std::string::npos) continue;
    ++volumes;
    const CliResult r =
        run("extract '" + e.path().string() + "' --iso auto -q -o a.ply --stats a.json");
    ASSERT_EQ(r.code, 0) << name << r.err;
    EXPECT_GT(json_of(dir_ / "a.json")["triangles"].get<int>(), 1000) << name;
  }
  EXPECT_GT(volumes, 0);
}

TEST_F(CliOutputs, IsoAutoFindsASurfaceInTheDicomSeries) {
  const fs::path series = isotile::testing::shared_volume("dicom_uih_t1_head_slab");
  ISOTILE_REQUIRE_SHARED(series);
  if (!isotile::itk_available()) ISOTILE_SKIP(Itk, "built without ITK");
  for (const std::string memory : {"", " --memory 64MiB"}) {
    const CliResult r =
        run("extract '" + series.string() + "' --iso auto -q -o a.ply --stats a.json" + memory);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_GT(json_of(dir_ / "a.json")["triangles"].get<int>(), 1000);
  }
}

}  // namespace
