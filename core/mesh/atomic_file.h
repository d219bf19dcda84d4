// A file that appears under its final name only when complete.
//
// Data goes to a file without a name in the target's folder (O_TMPFILE), which vanishes however
// the process ends, SIGKILL and the OOM killer included; commit() flushes and fsyncs it, links it
// as "<dir>/.<name>.tmp-<pid>-<n><ext>" (<ext> the name's extension) and renames that over the
// target. Where the file system has no O_TMPFILE (or /proc is missing), the data goes to that
// named temporary from the start. Destroying an uncommitted AtomicFile removes the temporary. The
// names of all named temporaries are also kept in a process-wide list so that
// remove_pending_temporaries() (called from the CLI's SIGINT/SIGTERM handler; async-signal-safe)
// can delete them on Ctrl-C.
//
// Only a regular file is ever renamed over (resolve_output below says what a path is):
// - a path that does not exist yet, or a regular file: the temporary-then-rename write (a
//   replaced file's permission bits are kept; a file the process may not write is refused);
// - a symbolic link is followed (link by link), and what it leads to is written as above: a
//   regular file's target is replaced atomically and the link itself stays a link;
// - a link into /proc/self/fd (/dev/stdout, /dev/stderr, /dev/fd/N) is written in place through
//   the process's own descriptor, so that `--stats /dev/stdout >> log` appends to the log;
// - an existing character device (/dev/null) or FIFO is opened and written in place: there is no
//   temporary, and a failed run may leave part of the data there;
// - a directory, a socket, a block device: refused (IoError).
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

namespace isotile {

// How a path is written.
struct OutputTarget {
  enum class Kind {
    NewFile,      // nothing there yet: created by a rename
    RegularFile,  // replaced by a rename
    Device,       // an existing character device or FIFO, opened and written in place
    Descriptor,   // a link into /proc/self/fd: written in place through descriptor `fd`
  };
  Kind kind = Kind::NewFile;
  // Where the data ends up: the path with every symbolic link followed (Device, NewFile,
  // RegularFile).
  std::filesystem::path path;
  int fd = -1;  // Descriptor only
  // In place: whether positioned writes (write_at) work there. They do not on a FIFO, a
  // character device or a descriptor (which may be a pipe, or a file opened for appending).
  bool in_place() const { return kind == Kind::Device || kind == Kind::Descriptor; }
};

// Says how `path` would be written, without writing anything (a FIFO is not opened). Throws
// IoError naming the path when it cannot be written: a directory, a socket, a block device, a
// folder that does not exist or is not writable, a file or device without write permission, a
// closed descriptor, a link loop.
OutputTarget resolve_output(const std::filesystem::path& path);

// Whether two paths name one file: the same device and inode where both lead to a file (links
// followed; a pipe or terminal behind /dev/stdout included, /dev/null never), else the same
// place of creation: every link followed, a dangling one's target included, and the path made
// absolute with `.`, `..` and the links of its existing folders resolved.
bool same_file(const std::filesystem::path& a, const std::filesystem::path& b);

// resolve_output(), and for writers that place records at offsets out of order (write_at: the
// out-of-core and MPI writers) an IoError when the target would be written in place. Call it
// before any work, so that a bad output fails at once.
OutputTarget check_output(const std::filesystem::path& path, bool positioned_writes = false);

class AtomicFile {
 public:
  // How the writer places its bytes. Streamed: through a large stdio buffer (4 MiB), so that big
  // blocks pass in few syscalls. Positioned: the records go with write_at(), straight to the
  // descriptor, and only the header passes through stdio, whose own small buffer serves it.
  enum class Writes { Streamed, Positioned };
  // Throws IoError when the path cannot be written (resolve_output) or the temporary cannot be
  // created.
  explicit AtomicFile(const std::filesystem::path& target, Writes writes = Writes::Streamed);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::FILE* stream() { return file_; }
  // Where the data goes until commit(): other writers of the same file (MPI ranks) open it there.
  // Gives a temporary without a name its name first (a process killed from then on leaves it).
  const std::filesystem::path& temp_path();
  // Writes n bytes; throws IoError on a short write (e.g. disk full).
  void write(const void* data, std::size_t n);
  // Writes n bytes at byte `offset`, wherever the stream is (a file written out of order, e.g.
  // brick by brick with every record's place known in advance); throws IoError on failure, and
  // on a target written in place (check_output(path, true) refuses those before any work).
  void write_at(std::uint64_t offset, const void* data, std::size_t n);
  // Flush, fsync, close and rename over the target; throws IoError on any failure (and then the
  // temporary is removed). In place: flush and close.
  void commit();
  // Whether the data goes straight to the target (a device, a FIFO, a descriptor).
  bool in_place() const { return in_place_; }

 private:
  void discard() noexcept;
  void name_temporary();
  std::filesystem::path target_;
  std::filesystem::path final_;  // target_ with its symbolic links followed
  bool in_place_ = false;
  // stdio's buffer in place and for a temporary without a name (a named one's sits with its slot)
  std::unique_ptr<char[]> buffer_;
  std::filesystem::path temp_;
  // The temporary's name but for its number: "<dir>/.<name>.tmp-<pid>-" and "<ext>".
  std::string temp_prefix_, temp_extension_;
  bool anonymous_ = false;  // an O_TMPFILE not linked yet
  std::FILE* file_ = nullptr;
  int slot_ = -1;
};

// A run's renames held back to its end: while a HeldCommits lives, AtomicFile::commit() of a file
// written by rename flushes, syncs and closes it as before and leaves it under its temporary name
// (remove_pending_temporaries() still removes it); commit() renames every held file over its
// target, in the order they were committed, and a HeldCommits ended without commit() removes
// them. The CLI holds a run's outputs so that a run that fails or is cancelled after its mesh is
// written (a stats file that cannot be written, the --stats measures, --render) leaves every
// output as it was, where the mesh had already replaced the old one. One at a time, per process.
class HeldCommits {
 public:
  HeldCommits();
  ~HeldCommits();
  HeldCommits(const HeldCommits&) = delete;
  HeldCommits& operator=(const HeldCommits&) = delete;
  // Renames the held files; throws IoError naming the first that cannot be renamed (it and those
  // after it are removed; those before it are in place).
  void commit();
  // Where the data written for `path` is: a held file's temporary, else `path` (for a reader of
  // an output the same run wrote: --render out of core draws the mesh file).
  static std::filesystem::path readable(const std::filesystem::path& path);
};

// Async-signal-safe: unlinks every temporary of a live AtomicFile, and every tracked one.
void remove_pending_temporaries() noexcept;

// A handler for the signals that end the process (the CLI's, the Python module's during a run):
// remove_pending_temporaries(), then the signal's default action.
extern "C" void remove_temporaries_and_reraise(int sig);

// Tracks a temporary another process's AtomicFile created and this one writes into too (an MPI
// rank), so that this process's SIGINT/SIGTERM removes it as well; -1 when the table is full.
int track_temporary(const std::filesystem::path& path) noexcept;
void untrack_temporary(int slot) noexcept;

}  // namespace isotile
