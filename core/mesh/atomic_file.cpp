#include "core/mesh/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "core/errors.h"

namespace isotile {

namespace {

// The signal handler may only look at plain memory, so the names of live temporaries sit in a
// fixed table rather than in a container that could be mid-reallocation when the signal lands.
constexpr int kSlots = 64;
constexpr std::size_t kMaxPath = 4096;
// Large enough that the writers' big blocks pass through stdio in few syscalls.
constexpr std::size_t kBufferSize = std::size_t{4} << 20;

static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs lock-free flags");

char g_paths[kSlots][kMaxPath];
// claimed: the slot belongs to a live AtomicFile. ready: its path is complete and may be
// unlinked by the handler. Two flags so that the handler never reads a half-written path.
std::atomic<bool> g_claimed[kSlots];
std::atomic<bool> g_ready[kSlots];
// The stdio buffer lives with the slot: setvbuf needs it to outlive fclose.
char* g_buffers[kSlots];
std::atomic<unsigned long> g_counter{0};

// -1 when the table is full or the path too long: that file then just misses Ctrl-C cleanup.
int claim_slot(const std::string& path) {
  if (path.size() + 1 > kMaxPath) return -1;
  for (int i = 0; i < kSlots; ++i) {
    bool expected = false;
    if (g_claimed[i].compare_exchange_strong(expected, true, std::memory_order_acquire)) {
      std::memcpy(g_paths[i], path.c_str(), path.size() + 1);
      g_ready[i].store(true, std::memory_order_release);
      return i;
    }
  }
  return -1;
}

void release_slot(int slot) {
  if (slot < 0) return;
  g_ready[slot].store(false, std::memory_order_release);
  std::free(g_buffers[slot]);
  g_buffers[slot] = nullptr;
  g_claimed[slot].store(false, std::memory_order_release);
}

std::string describe(int err) {
  return std::strerror(err);
}

[[noreturn]] void refuse(const std::filesystem::path& path, const std::string& why) {
  throw IoError("cannot write " + path.string() + ": " + why);
}

// The descriptor number when `path` names one of this process's descriptors (/proc/self/fd/N,
// /proc/thread-self/fd/N, /proc/<own pid>/fd/N, /dev/fd/N), whose link the kernel resolves to
// whatever the descriptor holds (a pipe, a terminal, a file opened for appending).
int descriptor_of(const std::filesystem::path& path) {
  const std::string s = path.lexically_normal().string();
  for (const std::string& dir :
       {std::string("/proc/self/fd/"), std::string("/dev/fd/"),
        std::string("/proc/thread-self/fd/"),
        "/proc/" + std::to_string(static_cast<long>(::getpid())) + "/fd/"}) {
    if (s.size() <= dir.size() || s.compare(0, dir.size(), dir) != 0) continue;
    const std::string n = s.substr(dir.size());
    if (n.size() > 9 || n.find_first_not_of("0123456789") != std::string::npos) return -1;
    return std::stoi(n);
  }
  return -1;
}

void check_folder(const std::filesystem::path& given, const std::filesystem::path& file) {
  const std::filesystem::path dir = file.parent_path().empty() ? "." : file.parent_path();
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0) {
    const int err = errno;
    refuse(given, err == ENOENT ? "folder " + dir.string() + " does not exist"
                                : "folder " + dir.string() + ": " + describe(err));
  }
  if (!S_ISDIR(st.st_mode)) refuse(given, dir.string() + " is not a folder");
  // The temporary is created beside the target and renamed over it.
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    refuse(given, "folder " + dir.string() + " is not writable (" + describe(errno) + ")");
}

}  // namespace

OutputTarget resolve_output(const std::filesystem::path& path) {
  if (path.empty()) refuse(path, "empty path");
  OutputTarget t;
  std::filesystem::path p = path;
  // Link by link, as the kernel would, so that a link into /proc/self/fd is seen before the
  // kernel turns it into what the descriptor holds.
  for (int hop = 0;; ++hop) {
    if (hop == 40) refuse(path, describe(ELOOP));
    if (const int fd = descriptor_of(p); fd >= 0) {
      if (::fcntl(fd, F_GETFL) < 0) refuse(path, "descriptor " + std::to_string(fd) + " is closed");
      if ((::fcntl(fd, F_GETFL) & O_ACCMODE) == O_RDONLY)
        refuse(path, "descriptor " + std::to_string(fd) + " is open for reading only");
      t.kind = OutputTarget::Kind::Descriptor;
      t.fd = fd;
      t.path = p;
      return t;
    }
    struct stat st {};
    if (::lstat(p.c_str(), &st) != 0) {
      const int err = errno;
      if (err != ENOENT) refuse(path, describe(err));
      check_folder(path, p);
      t.kind = OutputTarget::Kind::NewFile;
      t.path = p;
      return t;
    }
    if (S_ISLNK(st.st_mode)) {
      std::error_code ec;
      const std::filesystem::path to = std::filesystem::read_symlink(p, ec);
      if (ec) refuse(path, ec.message());
      p = to.is_absolute() ? to : p.parent_path() / to;
      continue;
    }
    t.path = p;
    if (S_ISREG(st.st_mode)) {
      check_folder(path, p);
      // The rename would replace a file its owner made read-only, as `>` would not.
      if (::access(p.c_str(), W_OK) != 0)
        refuse(path, "the file is not writable (" + describe(errno) + ")");
      t.kind = OutputTarget::Kind::RegularFile;
      return t;
    }
    if (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode)) {
      if (::access(p.c_str(), W_OK) != 0) refuse(path, describe(errno));
      t.kind = OutputTarget::Kind::Device;
      return t;
    }
    if (S_ISDIR(st.st_mode)) refuse(path, "it is a directory");
    if (S_ISSOCK(st.st_mode)) refuse(path, "it is a socket");
    if (S_ISBLK(st.st_mode)) refuse(path, "it is a block device");
    refuse(path, "not a regular file, character device or FIFO");
  }
}

namespace {

// Where a path that does not lead to a file yet would be created: its links followed one by one
// (a dangling link's target is what gets created), then made absolute with `.`, `..` and the
// links of its existing folders resolved. weakly_canonical alone left a relative path whose
// first folder does not exist as it was ("o.ply" against "./o.ply" made absolute), and took a
// dangling link for a name of its own.
std::filesystem::path where_created(std::filesystem::path p) {
  for (int hop = 0; hop < 40; ++hop) {
    struct stat st {};
    if (::lstat(p.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) break;
    std::error_code ec;
    const std::filesystem::path to = std::filesystem::read_symlink(p, ec);
    if (ec) break;
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  std::error_code ec;
  const std::filesystem::path absolute = std::filesystem::absolute(p, ec);
  if (ec) return p.lexically_normal();
  const std::filesystem::path canonical = std::filesystem::weakly_canonical(absolute, ec);
  return ec ? absolute.lexically_normal() : canonical;
}

}  // namespace

bool same_file(const std::filesystem::path& a, const std::filesystem::path& b) {
  // Where both lead to a file, its device and inode: std::filesystem::equivalent answers only
  // for regular files and folders in libstdc++, and took a pipe behind /dev/stdout for none.
  // /dev/null takes any number of writers.
  struct stat sa {};
  struct stat sb {};
  const bool has_a = ::stat(a.c_str(), &sa) == 0, has_b = ::stat(b.c_str(), &sb) == 0;
  if (has_a && has_b) {
    if (sa.st_dev != sb.st_dev || sa.st_ino != sb.st_ino) return false;
    struct stat null {};
    return !(::stat("/dev/null", &null) == 0 && null.st_dev == sa.st_dev &&
             null.st_ino == sa.st_ino);
  }
  if (has_a != has_b) return false;
  return where_created(a) == where_created(b);
}

OutputTarget check_output(const std::filesystem::path& path, bool positioned_writes) {
  const OutputTarget t = resolve_output(path);
  if (positioned_writes && t.in_place())
    refuse(path,
           "this writer places records out of order and needs a regular file (or a new path); "
           "a device, FIFO or standard output cannot take it");
  return t;
}

AtomicFile::AtomicFile(const std::filesystem::path& target, Writes writes) : target_(target) {
  // A positioned writer touches no more of a large buffer than its header's bytes, yet the buffer
  // is taken from the heap, which in the CLI keeps freed blocks for reuse: it landed on blocks
  // freed but still resident, and the next arrays took fresh pages instead. Out of core, the count
  // pass's read buffer (the whole volume's samples under Macet max's halo) sat idle under it
  // while each part read into new pages: Macet max on gyroid 80^3 at --memory 10MiB peaked 10.1-
  // 10.3 MiB above its baseline, 8.0-8.2 without the buffer.
  const bool large_buffer = writes == Writes::Streamed;
  const OutputTarget t = resolve_output(target);
  final_ = t.path;
  if (t.in_place()) {
    in_place_ = true;
    // What this process already wrote to stdout or stderr through stdio goes first.
    if (t.kind == OutputTarget::Kind::Descriptor && (t.fd == 1 || t.fd == 2))
      std::fflush(t.fd == 1 ? stdout : stderr);
    // A duplicate of the descriptor shares its offset and flags (O_APPEND of `>> log`).
    const int fd = t.kind == OutputTarget::Kind::Descriptor
                       ? ::fcntl(t.fd, F_DUPFD_CLOEXEC, 3)
                       : ::open(final_.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
    if (fd < 0) refuse(target_, describe(errno));
    file_ = ::fdopen(fd, "wb");
    if (!file_) {
      const int err = errno;
      ::close(fd);
      refuse(target_, describe(err));
    }
    // The same large buffer as a temporary's (it outlives fclose: a member).
    if (large_buffer) {
      buffer_.reset(new (std::nothrow) char[kBufferSize]);
      if (buffer_) std::setvbuf(file_, buffer_.get(), _IOFBF, kBufferSize);
    }
    return;
  }
  // Built with append: GCC 12 gives a false -Wrestrict for "." + std::string at -O2.
  std::string prefix(1, '.');
  // The target's name cut to leave room for the suffix within a name's 255 bytes (NAME_MAX on
  // Linux file systems): a legal name of 250 bytes must not fail after all the work.
  const std::string name = final_.filename().string();
  prefix.append(name, 0, std::min<std::size_t>(name.size(), 200));
  prefix.append(".tmp-");
  prefix.append(std::to_string(static_cast<long>(::getpid())));
  prefix.append("-");
  // The target's extension last, so that a reader of the temporary (--render of a mesh whose
  // rename is held: HeldCommits) tells its format as by the target's name.
  std::string extension = final_.extension().string();
  if (extension.size() > 16) extension.clear();
  const std::filesystem::path dir = final_.parent_path().empty() ? "." : final_.parent_path();
  temp_prefix_ = (dir / prefix).string();
  temp_extension_ = extension;
  // Without a name first: a process killed before commit() (SIGKILL, the OOM killer) leaves
  // nothing, where a named temporary of the mesh's size stayed, hidden, beside the output. Its
  // name comes through /proc/self/fd at commit(), so it is used only where that is there.
  const int fd = ::open(dir.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0666);
  if (fd >= 0) {
    if (::access(("/proc/self/fd/" + std::to_string(fd)).c_str(), F_OK) == 0 &&
        (file_ = ::fdopen(fd, "wb")) != nullptr) {
      anonymous_ = true;
      if (large_buffer) {
        buffer_.reset(new (std::nothrow) char[kBufferSize]);
        if (buffer_) std::setvbuf(file_, buffer_.get(), _IOFBF, kBufferSize);
      }
    } else {
      ::close(fd);
    }
  }
  // "x" makes creation exclusive; a leftover from a killed process with a reused pid must not be
  // shared, so try the next number instead.
  for (int attempt = 0; !anonymous_ && attempt < 100; ++attempt) {
    const unsigned long n = g_counter.fetch_add(1, std::memory_order_relaxed);
    temp_ = temp_prefix_ + std::to_string(n) + temp_extension_;
    file_ = std::fopen(temp_.c_str(), "wbx");
    if (file_ || errno != EEXIST) break;
  }
  if (!file_) {
    const int err = errno;
    throw IoError("cannot write " + target_.string() + ": " + describe(err));
  }
  // A replaced file keeps its permissions (a private 0600 file must not become world-readable
  // 0644): the temporary takes them before any data goes in. Set-id bits are not carried over;
  // the owner (now this user, as after any rename) keeps reading and writing it, as another
  // user's file writable through its group gave a file its new owner could not replace, nor MPI
  // ranks open. Best effort, as on a file system without modes.
  struct stat old {};
  if (t.kind == OutputTarget::Kind::RegularFile && ::stat(final_.c_str(), &old) == 0)
    (void)::fchmod(fileno(file_), (old.st_mode & 01777) | S_IRUSR | S_IWUSR);
  if (anonymous_) return;
  slot_ = claim_slot(temp_.string());
  if (slot_ >= 0 && large_buffer) {
    g_buffers[slot_] = static_cast<char*>(std::malloc(kBufferSize));
    if (g_buffers[slot_]) std::setvbuf(file_, g_buffers[slot_], _IOFBF, kBufferSize);
  }
}

void AtomicFile::name_temporary() {
  if (!anonymous_) return;
  const std::string self = "/proc/self/fd/" + std::to_string(::fileno(file_));
  for (int attempt = 0; attempt < 100; ++attempt) {
    const unsigned long n = g_counter.fetch_add(1, std::memory_order_relaxed);
    const std::string name = temp_prefix_ + std::to_string(n) + temp_extension_;
    if (::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, name.c_str(), AT_SYMLINK_FOLLOW) == 0) {
      temp_ = name;
      anonymous_ = false;
      slot_ = claim_slot(name);
      return;
    }
    if (errno != EEXIST) break;
  }
  const int err = errno;
  throw IoError("cannot write " + target_.string() + ": " + describe(err));
}

const std::filesystem::path& AtomicFile::temp_path() {
  name_temporary();
  return temp_;
}

AtomicFile::~AtomicFile() {
  discard();
}

void AtomicFile::write(const void* data, std::size_t n) {
  if (!file_) throw IoError("cannot write " + target_.string() + ": file already closed");
  if (n == 0) return;
  if (std::fwrite(data, 1, n, file_) != n) {
    const int err = errno;
    throw IoError("cannot write " + target_.string() + ": " + describe(err));
  }
}

void AtomicFile::write_at(std::uint64_t offset, const void* data, std::size_t n) {
  if (!file_) throw IoError("cannot write " + target_.string() + ": file already closed");
  if (in_place_)
    refuse(target_, "positioned writes need a regular file, not a device, FIFO or descriptor");
  // Buffered writes must reach the descriptor before a positioned one can land beside them.
  if (std::fflush(file_) != 0) {
    const int err = errno;
    throw IoError("cannot write " + target_.string() + ": " + describe(err));
  }
  const int fd = fileno(file_);
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t done = ::pwrite(fd, p, n, static_cast<off_t>(offset));
    if (done < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      throw IoError("cannot write " + target_.string() + ": " + describe(err));
    }
    p += done;
    n -= static_cast<std::size_t>(done);
    offset += static_cast<std::uint64_t>(done);
  }
}

namespace {

struct Held {
  std::filesystem::path target, final, temp;
  int slot = -1;
};
std::mutex g_held_mutex;
std::vector<Held>* g_held = nullptr;  // while a HeldCommits lives

}  // namespace

HeldCommits::HeldCommits() {
  std::lock_guard lock(g_held_mutex);
  if (g_held) throw std::logic_error("HeldCommits: one at a time");
  g_held = new std::vector<Held>();
}

HeldCommits::~HeldCommits() {
  std::lock_guard lock(g_held_mutex);
  for (const Held& h : *g_held) {
    ::unlink(h.temp.c_str());
    release_slot(h.slot);
  }
  delete g_held;
  g_held = nullptr;
}

void HeldCommits::commit() {
  std::lock_guard lock(g_held_mutex);
  std::vector<Held>& held = *g_held;
  for (std::size_t i = 0; i < held.size(); ++i) {
    std::error_code ec;
    std::filesystem::rename(held[i].temp, held[i].final, ec);
    if (ec) {
      // This one and those after it stay temporaries: the destructor removes them.
      held.erase(held.begin(), held.begin() + static_cast<std::ptrdiff_t>(i));
      throw IoError("cannot write " + held.front().target.string() + ": " + ec.message());
    }
    release_slot(held[i].slot);
  }
  held.clear();
}

std::filesystem::path HeldCommits::readable(const std::filesystem::path& path) {
  std::lock_guard lock(g_held_mutex);
  if (g_held)
    for (const Held& h : *g_held)
      if (h.target == path) return h.temp;
  return path;
}

void AtomicFile::commit() {
  if (!file_) throw IoError("cannot write " + target_.string() + ": file already closed");
  auto fail = [&](int err) {
    discard();
    throw IoError("cannot write " + target_.string() + ": " + describe(err));
  };
  if (std::fflush(file_) != 0) fail(errno);
  // A device or pipe has nothing to sync (fsync fails with EINVAL there).
  if (!in_place_ && ::fsync(::fileno(file_)) != 0) fail(errno);
  try {
    name_temporary();
  } catch (const IoError&) {
    discard();
    throw;
  }
  std::FILE* f = file_;
  file_ = nullptr;
  if (std::fclose(f) != 0) fail(errno);
  if (in_place_) return;
  {
    std::lock_guard lock(g_held_mutex);
    if (g_held) {
      g_held->push_back({target_, final_, temp_, slot_});
      slot_ = -1;
      temp_.clear();
      return;
    }
  }
  std::error_code ec;
  // Over the link's target, not the link: a symbolic link to a regular file stays a link.
  std::filesystem::rename(temp_, final_, ec);
  if (ec) {
    discard();
    throw IoError("cannot write " + target_.string() + ": " + ec.message());
  }
  release_slot(slot_);
  slot_ = -1;
  temp_.clear();
}

void AtomicFile::discard() noexcept {
  if (file_) {
    std::fclose(file_);
    file_ = nullptr;
  }
  if (!temp_.empty()) {
    ::unlink(temp_.c_str());
    temp_.clear();
  }
  release_slot(slot_);
  slot_ = -1;
}

void remove_pending_temporaries() noexcept {
  for (int i = 0; i < kSlots; ++i) {
    if (g_ready[i].load(std::memory_order_acquire)) ::unlink(g_paths[i]);
  }
}

extern "C" void remove_temporaries_and_reraise(int sig) {
  remove_pending_temporaries();
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

int track_temporary(const std::filesystem::path& path) noexcept {
  try {
    return claim_slot(path.string());
  } catch (...) {
    return -1;
  }
}

void untrack_temporary(int slot) noexcept {
  release_slot(slot);
}

}  // namespace isotile
