// A file that appears under its final name only when complete.
//
// Data goes to "<dir>/.<name>.tmp-<pid>-<n>"; commit() flushes, fsyncs and renames it over the
// target. Destroying an uncommitted AtomicFile removes the temporary file. The names of all open
// temporaries are also kept in a process-wide list so that remove_pending_temporaries() (called
// from the CLI's SIGINT/SIGTERM handler; async-signal-safe) can delete them on Ctrl-C.
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>

namespace isotile {

class AtomicFile {
 public:
  // Throws IoError when the temporary cannot be created (e.g. the directory does not exist).
  explicit AtomicFile(const std::filesystem::path& target);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::FILE* stream() { return file_; }
  // Where the data goes until commit(): other writers of the same file (MPI ranks) open it there.
  const std::filesystem::path& temp_path() const { return temp_; }
  // Writes n bytes; throws IoError on a short write (e.g. disk full).
  void write(const void* data, std::size_t n);
  // Writes n bytes at byte `offset`, wherever the stream is (a file written out of order, e.g.
  // brick by brick with every record's place known in advance); throws IoError on failure.
  void write_at(std::uint64_t offset, const void* data, std::size_t n);
  // Flush, fsync, close and rename over the target; throws IoError on any failure (and then the
  // temporary is removed).
  void commit();

 private:
  void discard() noexcept;
  std::filesystem::path target_;
  std::filesystem::path temp_;
  std::FILE* file_ = nullptr;
  int slot_ = -1;
};

// Async-signal-safe: unlinks every temporary of a live AtomicFile, and every tracked one.
void remove_pending_temporaries() noexcept;

// Tracks a temporary another process's AtomicFile created and this one writes into too (an MPI
// rank), so that this process's SIGINT/SIGTERM removes it as well; -1 when the table is full.
int track_temporary(const std::filesystem::path& path) noexcept;
void untrack_temporary(int slot) noexcept;

}  // namespace isotile
