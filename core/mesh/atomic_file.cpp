#include "core/mesh/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string>
#include <system_error>

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

}  // namespace

AtomicFile::AtomicFile(const std::filesystem::path& target) : target_(target) {
  // Built with append: GCC 12 gives a false -Wrestrict for "." + std::string at -O2.
  std::string prefix(1, '.');
  prefix.append(target.filename().string());
  prefix.append(".tmp-");
  prefix.append(std::to_string(static_cast<long>(::getpid())));
  prefix.append("-");
  // "x" makes creation exclusive; a leftover from a killed process with a reused pid must not be
  // shared, so try the next number instead.
  for (int attempt = 0; attempt < 100; ++attempt) {
    const unsigned long n = g_counter.fetch_add(1, std::memory_order_relaxed);
    temp_ = target.parent_path() / (prefix + std::to_string(n));
    file_ = std::fopen(temp_.c_str(), "wbx");
    if (file_ || errno != EEXIST) break;
  }
  if (!file_) {
    const int err = errno;
    throw IoError("cannot write " + target_.string() + ": " + describe(err));
  }
  slot_ = claim_slot(temp_.string());
  if (slot_ >= 0) {
    g_buffers[slot_] = static_cast<char*>(std::malloc(kBufferSize));
    if (g_buffers[slot_]) std::setvbuf(file_, g_buffers[slot_], _IOFBF, kBufferSize);
  }
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

void AtomicFile::commit() {
  if (!file_) throw IoError("cannot write " + target_.string() + ": file already closed");
  auto fail = [&](int err) {
    discard();
    throw IoError("cannot write " + target_.string() + ": " + describe(err));
  };
  if (std::fflush(file_) != 0) fail(errno);
  if (::fsync(::fileno(file_)) != 0) fail(errno);
  std::FILE* f = file_;
  file_ = nullptr;
  if (std::fclose(f) != 0) fail(errno);
  std::error_code ec;
  std::filesystem::rename(temp_, target_, ec);
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
