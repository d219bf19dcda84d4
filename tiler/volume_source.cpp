#include "tiler/volume_source.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <optional>
#include <vector>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/volume/procedural_fields.h"

namespace isotile {

namespace {

void swap_sample_bytes(void* data, std::size_t count, std::size_t size) {
  auto* b = static_cast<unsigned char*>(data);
  for (std::size_t i = 0; i < count; ++i, b += size) std::reverse(b, b + size);
}

class FieldSource final : public VolumeSource {
 public:
  explicit FieldSource(const FieldSpec& spec) : spec_(spec) {
    type = ScalarType::Float32;
    dims = {spec.n, spec.n, spec.n};
  }
  void read(const Box3& box, void* out) override {
    fill_field_box(spec_, box, static_cast<float*>(out));
  }

 private:
  FieldSpec spec_;
};

// `bytes` at `offset` of the open file `fd` (named `name`) into `dst`.
void read_exactly(int fd, const std::string& name, char* dst, std::int64_t bytes,
                  std::int64_t offset) {
  std::int64_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::pread(fd, dst + done, static_cast<std::size_t>(bytes - done),
                              static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0)
      throw IoError("cannot read " + name + ": " +
                    (n == 0 ? std::string("file is shorter than its dims say")
                            : std::string(std::strerror(errno))));
    done += n;
  }
}

// What says that a file changed: its identity, size and modification time.
struct FileStamp {
  dev_t dev = 0;
  ino_t ino = 0;
  off_t size = 0;
  std::int64_t mtime_ns = 0;
  static FileStamp of(const struct stat& st) {
    return {st.st_dev, st.st_ino, st.st_size,
            std::int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec};
  }
  bool operator==(const FileStamp&) const = default;
};

[[noreturn]] void throw_changed(const std::string& file) {
  throw InputError(file +
                   ": the input changed during the run (its size or modification time): an "
                   "out-of-core run reads it twice, and the mesh would mix old and new samples; "
                   "run it again once the file stays as it is");
}

// The stamp of an open descriptor, or of the file a name holds; nullopt for what is not a
// regular file.
std::optional<FileStamp> stamp_of(int fd) {
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) return std::nullopt;
  return FileStamp::of(st);
}
std::optional<FileStamp> stamp_of(const std::string& file) {
  struct stat st {};
  if (::stat(file.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return std::nullopt;
  return FileStamp::of(st);
}

// Samples stored plainly in one file from byte `offset` on (raw files, NRRD's raw data).
struct PlainLayout {
  std::string file;
  std::uint64_t offset = 0;
  ScalarType type = ScalarType::UInt8;
  Index3 dims{0, 0, 0};
  bool swap = false;         // stored in the other byte order
  bool bytes_after = false;  // the file may go on past the samples (PlainData::bytes_after)
};

class RawFileSource final : public VolumeSource {
 public:
  explicit RawFileSource(const PlainLayout& layout)
      : file_name_(layout.file), offset_(layout.offset), swap_(layout.swap) {
    name = layout.file;
    type = layout.type;
    dims = layout.dims;
    fd_ = ::open(name.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw IoError("cannot open " + name + ": " + std::strerror(errno));
    stamp_ = stamp_of(fd_);
    try {  // a throwing constructor runs no destructor: the descriptor is closed here
      if (stamp_)
        check_plain_size(name, static_cast<std::uint64_t>(stamp_->size), offset_, type, dims,
                         layout.bytes_after);
      else
        checked_volume_bytes(type, dims);
    } catch (...) {
      ::close(fd_);
      throw;
    }
  }
  ~RawFileSource() override {
    if (fd_ >= 0) ::close(fd_);
  }

  // The open descriptor's file: a file renamed over the name later is not what is read.
  void check_unchanged() const override {
    if (stamp_ && stamp_of(fd_) != stamp_) throw_changed(file_name_);
  }

  void read(const Box3& box, void* out) override {
    const auto size = static_cast<std::int64_t>(scalar_size(type));
    // Rows that are consecutive in the file go in one read: whole rows make a plane's rows one
    // run, whole planes the box one run (one system call per 2 KiB row costs more than the copy).
    const bool whole_rows = box.lo[0] == 0 && box.hi[0] == dims[0];
    const bool whole_planes = whole_rows && box.lo[1] == 0 && box.hi[1] == dims[1];
    const std::int64_t run_rows = whole_planes ? box.extent(1) * box.extent(2)
                                  : whole_rows ? box.extent(1)
                                               : 1;
    const std::int64_t run_bytes = run_rows * box.extent(0) * size;
    const std::int64_t rows = box.extent(1) * box.extent(2);
    auto* dst = static_cast<char*>(out);
    for (std::int64_t r = 0; r < rows; r += run_rows, dst += run_bytes) {
      const std::int64_t k = box.lo[2] + r / box.extent(1), j = box.lo[1] + r % box.extent(1);
      const std::int64_t offset =
          static_cast<std::int64_t>(offset_) + ((k * dims[1] + j) * dims[0] + box.lo[0]) * size;
      read_exactly(fd_, name, dst, run_bytes, offset);
    }
    if (swap_)
      swap_sample_bytes(out,
                        static_cast<std::size_t>(box.extent(0) * box.extent(1) * box.extent(2)),
                        static_cast<std::size_t>(size));
  }

 private:
  std::string file_name_;  // the file holding the samples (a NRRD header's data file)
  int fd_ = -1;
  std::optional<FileStamp> stamp_;
  std::uint64_t offset_ = 0;
  bool swap_ = false;
};

// A stack of files of one plane each, stored plainly (TIFF slices: PlainData::planes). Each read
// opens the files of its planes in turn: a stack may hold more files than a process may keep
// open.
class PlaneFilesSource final : public VolumeSource {
 public:
  PlaneFilesSource(const PlainData& data, bool swap) : planes_(data.planes), swap_(swap) {
    name = data.planes.front().file;
    type = data.type;
    dims = data.dims;
    checked_volume_bytes(type, dims);
    stamps_.reserve(planes_.size());
    for (const PlainData::Plane& plane : planes_) stamps_.push_back(stamp_of(plane.file));
  }

  // Each read opens the files by name: a file renamed over one counts as a change too.
  void check_unchanged() const override {
    for (std::size_t k = 0; k < planes_.size(); ++k)
      if (stamp_of(planes_[k].file) != stamps_[k]) throw_changed(planes_[k].file);
  }

  void read(const Box3& box, void* out) override {
    const auto size = static_cast<std::int64_t>(scalar_size(type));
    const bool whole_rows = box.lo[0] == 0 && box.hi[0] == dims[0];
    const std::int64_t run_rows = whole_rows ? box.extent(1) : 1;
    const std::int64_t run_bytes = run_rows * box.extent(0) * size;
    auto* dst = static_cast<char*>(out);
    for (std::int64_t k = box.lo[2]; k < box.hi[2]; ++k) {
      const PlainData::Plane& plane = planes_[static_cast<std::size_t>(k)];
      const int fd = ::open(plane.file.c_str(), O_RDONLY | O_CLOEXEC);
      if (fd < 0) throw IoError("cannot open " + plane.file + ": " + std::strerror(errno));
      try {
        for (std::int64_t j = box.lo[1]; j < box.hi[1]; j += run_rows, dst += run_bytes)
          read_exactly(fd, plane.file, dst, run_bytes,
                       static_cast<std::int64_t>(plane.offset) + (j * dims[0] + box.lo[0]) * size);
      } catch (...) {
        ::close(fd);
        throw;
      }
      ::close(fd);
    }
    if (swap_)
      swap_sample_bytes(out,
                        static_cast<std::size_t>(box.extent(0) * box.extent(1) * box.extent(2)),
                        static_cast<std::size_t>(size));
  }

 private:
  std::vector<PlainData::Plane> planes_;
  std::vector<std::optional<FileStamp>> stamps_;
  bool swap_ = false;
};

// gzip'd raw: one pass decompresses the stream once, front to back, with a bounded buffer: the
// planner asks for whole x-y slabs in ascending z, which may overlap by their halos, so the last
// planes read are kept for the next box. The stream starts at the layout's offset (an NRRD's
// attached gzip data follows its header).
class GzipRawSource final : public VolumeSource {
 public:
  // `why_gzip`: what says the data is gzip'd, for the error where it is not.
  GzipRawSource(const PlainLayout& layout, const std::string& why_gzip)
      : file_name_(layout.file), swap_(layout.swap) {
    name = layout.file;
    type = layout.type;
    dims = layout.dims;
    checked_volume_bytes(type, dims);
    const int fd = ::open(name.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw IoError("cannot open " + name + ": " + std::strerror(errno));
    // zlib takes the descriptor's position as the stream's start (gzrewind returns there).
    if (::lseek(fd, static_cast<off_t>(layout.offset), SEEK_SET) < 0) {
      const int err = errno;
      ::close(fd);
      throw IoError("cannot read " + name + ": " + std::strerror(err));
    }
    stamp_ = stamp_of(fd);
    file_ = gzdopen(fd, "rb");
    if (!file_) {
      ::close(fd);
      throw IoError("cannot open " + name + ": out of memory");
    }
    fd_ = fd;
    plane_bytes_ = static_cast<std::size_t>(dims[0] * dims[1]) * scalar_size(type);
    buffer_ = static_cast<unsigned>(
        std::clamp<std::size_t>(std::bit_ceil(plane_bytes_), 1u << 14, kMaxBuffer));
    // Before the first read, which gzdirect() is: later zlib keeps its default 8 KiB (it did
    // until 2026-11-28).
    gzbuffer(file_, buffer_);
    if (gzdirect(file_)) {
      gzclose(file_);
      throw InputError(name + ": not gzip data (" + why_gzip + "); rename it or recompress it");
    }
  }
  ~GzipRawSource() override {
    if (file_) gzclose(file_);
  }

  void check_unchanged() const override {
    if (stamp_ && stamp_of(fd_) != stamp_) throw_changed(file_name_);
  }

  bool sequential() const override { return true; }
  // zlib's input buffer, its output buffer (twice the size), the inflate window and state.
  std::uint64_t buffer_bytes() const override { return 3 * std::uint64_t{buffer_} + (40u << 10); }
  void set_overlap(std::int64_t planes) override {
    keep_planes_ = std::max<std::int64_t>(planes, 1);
  }
  void rewind() override {
    if (gzrewind(file_) != 0) throw IoError("cannot rewind " + name);
    next_plane_ = 0;
    end_checked_ = false;
    kept_.clear();
    kept_lo_ = 0;
  }

  void read(const Box3& box, void* out) override {
    if (box.lo[0] != 0 || box.lo[1] != 0 || box.hi[0] != dims[0] || box.hi[1] != dims[1])
      throw InputError(name + ": a gzip'd volume can only be read in whole x-y slabs");
    if (box.lo[2] < kept_lo_) throw InputError(name + ": gzip'd slabs must be read in ascending z");
    auto* dst = static_cast<char*>(out);
    for (std::int64_t k = box.lo[2]; k < box.hi[2]; ++k, dst += plane_bytes_) {
      if (k < next_plane_) {
        // A halo plane the previous slab read.
        std::memcpy(dst, kept_.data() + static_cast<std::size_t>(k - kept_lo_) * plane_bytes_,
                    plane_bytes_);
        continue;
      }
      while (next_plane_ < k) skip_plane();
      read_plane(dst);
    }
    if (next_plane_ == dims[2] && !end_checked_) check_end();
    // Keep the last planes: the next slab's lower halo starts at most this far back.
    const std::int64_t keep = std::min<std::int64_t>(box.extent(2), keep_planes_);
    kept_lo_ = box.hi[2] - keep;
    kept_.assign(
        static_cast<const char*>(out) +
            static_cast<std::size_t>(kept_lo_ - box.lo[2]) * plane_bytes_,
        static_cast<const char*>(out) + static_cast<std::size_t>(box.extent(2)) * plane_bytes_);
  }

 private:
  // zlib's buffer: a plane, within [16 KiB, 256 KiB]. Larger buffers do not decompress faster
  // (bonsai with --memory 64MiB: 0.16-0.19 s in all with 256 KiB and with 1 MiB) and count
  // against the memory budget; small volumes keep small ones, so small budgets still hold a slab.
  static constexpr std::size_t kMaxBuffer = std::size_t{1} << 18;
  int fd_ = -1;  // zlib's (gzdopen): closed by gzclose
  std::optional<FileStamp> stamp_;
  unsigned buffer_ = 1u << 14;
  // Planes the next box may share with this one (set_overlap: 2 halo + 1, so 9 for DC's Eno
  // Hermite data and 103 for Macet max).
  std::int64_t keep_planes_ = 8;

  void read_plane(char* dst) {
    std::size_t done = 0;
    while (done < plane_bytes_) {
      const unsigned chunk =
          static_cast<unsigned>(std::min<std::size_t>(plane_bytes_ - done, 1u << 30));
      const int n = gzread(file_, dst + done, chunk);
      int code = Z_OK;
      const char* message = gzerror(file_, &code);
      if (n < 0 || (code != Z_OK && code != Z_BUF_ERROR))
        throw InputError(file_name_ + ": corrupt gzip data (" + gzerror_text(file_name_, message) +
                         ")");
      // Z_BUF_ERROR with the whole chunk: zlib's look-ahead met the file's end, the trailer is
      // missing (check_end() says so after the last plane); with less, the samples are.
      if (n == 0 || (code == Z_BUF_ERROR && static_cast<unsigned>(n) < chunk))
        throw InputError(file_name_ + ": gzip data cut off: it ends after " +
                         std::to_string(static_cast<std::uint64_t>(next_plane_) * plane_bytes_ +
                                        done + static_cast<std::size_t>(std::max(n, 0))) +
                         " bytes but " + volume_text() + " (truncated file)");
      done += static_cast<std::size_t>(n);
    }
    if (swap_) swap_sample_bytes(dst, plane_bytes_ / scalar_size(type), scalar_size(type));
    ++next_plane_;
  }
  std::string volume_text() const {
    return std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]) +
           " " + std::string(scalar_name(type)) + " samples need " +
           std::to_string(plane_bytes_ * static_cast<std::uint64_t>(dims[2]));
  }
  // After the last plane: nothing more, and the gzip trailer (CRC, length) as zlib checks it, so
  // that a stream cut in its last bytes or corrupt is an error, as when read in core.
  void check_end() {
    char extra;
    const int n = gzread(file_, &extra, 1);
    int code = Z_OK;
    const char* message = gzerror(file_, &code);
    if (n == 1)
      throw InputError(file_name_ + ": gzip data holds more than the " +
                       std::to_string(plane_bytes_ * static_cast<std::uint64_t>(dims[2])) +
                       " bytes " + volume_text().substr(0, volume_text().find(" samples")) +
                       " samples need (too long)");
    if (code == Z_BUF_ERROR)
      throw InputError(file_name_ + ": gzip data cut off: all " +
                       std::to_string(plane_bytes_ * static_cast<std::uint64_t>(dims[2])) +
                       " bytes are there but the stream's end (CRC and length) is cut off "
                       "(truncated file)");
    if (n < 0 || code != Z_OK)
      throw InputError(file_name_ + ": corrupt gzip data (" + gzerror_text(file_name_, message) +
                       ")");
    end_checked_ = true;
  }
  bool end_checked_ = false;
  void skip_plane() {
    std::vector<char> scratch(plane_bytes_);
    read_plane(scratch.data());
  }

  gzFile file_ = nullptr;
  std::string file_name_;  // the file holding the stream (a NRRD header's data file)
  bool swap_ = false;
  std::size_t plane_bytes_ = 0;
  std::int64_t next_plane_ = 0;
  std::vector<char> kept_;
  std::int64_t kept_lo_ = 0;
};

// OpenVDB: the grid's sparse tree stays in memory (that is the format); boxes are densified from
// it.
class VdbSource final : public VolumeSource {
 public:
  explicit VdbSource(std::unique_ptr<VdbVolume> vdb) : vdb_(std::move(vdb)) {
    type = vdb_->type;
    dims = vdb_->dims;
    spacing = vdb_->spacing;
    origin = vdb_->origin;
  }
  void read(const Box3& box, void* out) override { vdb_->read_box(box, out); }

 private:
  std::unique_ptr<VdbVolume> vdb_;
};

// NRRD data teem cannot hand out box by box (several files, other encodings): read whole.
class InMemorySource final : public VolumeSource {
 public:
  explicit InMemorySource(Volume v) : volume_(std::move(v)) {
    type = volume_.type();
    dims = volume_.dims();
    spacing = volume_.spacing();
    origin = volume_.origin();
    world = volume_.world();
  }
  bool in_memory() const override { return true; }
  void read(const Box3& box, void* out) override {
    const std::size_t size = scalar_size(type);
    const std::size_t row = static_cast<std::size_t>(box.extent(0)) * size;
    auto* dst = static_cast<char*>(out);
    const auto* src = reinterpret_cast<const char*>(volume_.bytes());
    for (std::int64_t k = box.lo[2]; k < box.hi[2]; ++k)
      for (std::int64_t j = box.lo[1]; j < box.hi[1]; ++j, dst += row)
        std::memcpy(dst,
                    src + static_cast<std::size_t>((k * dims[1] + j) * dims[0] + box.lo[0]) * size,
                    row);
  }

 private:
  Volume volume_;
};

}  // namespace

std::unique_ptr<VolumeSource> open_volume_source(const std::string& input, const RawOptions& raw,
                                                 std::uint64_t memory_budget) {
  check_raw_overrides(raw);
  const bool native_big = std::endian::native == std::endian::big;
  std::unique_ptr<VolumeSource> source;
  const InputKind kind = input_kind(input);
  if (kind == InputKind::Mrc || is_itk_kind(kind)) {
    const VolumeHeader h = read_volume_header(input, raw);
    if (h.plain && !h.plain->planes.empty()) {
      source = std::make_unique<PlaneFilesSource>(*h.plain,
                                                  (h.plain->endian == Endian::Big) != native_big);
    } else if (h.plain) {
      source = std::make_unique<RawFileSource>(
          PlainLayout{h.plain->file, h.plain->offset, h.plain->type, h.plain->dims,
                      (h.plain->endian == Endian::Big) != native_big, h.plain->bytes_after});
    } else {
      const std::uint64_t bytes = checked_volume_bytes(h.type, h.dims);
      if (memory_budget > 0 && bytes > memory_budget)
        throw InputError(input + ": this " + h.format +
                         " input cannot be read by region (its samples are not stored plainly in "
                         "one file), and the whole volume (" +
                         std::to_string(bytes) + " bytes) does not fit --memory (" +
                         std::to_string(memory_budget) + " bytes)");
      source = std::make_unique<InMemorySource>(read_volume(input, raw));
    }
    source->name = input;
    source->spacing = h.spacing;
    source->origin = h.origin;
    source->world = h.world;
    source->series_uid = h.series_uid;
    source->series_description = h.series_description;
    return source;
  }
  const bool nrrd = kind == InputKind::Nrrd;
  const bool vdb = kind == InputKind::Vdb;
  if (!raw.series.empty()) throw InputError(input + ": --series applies to DICOM only");
  if (parse_field_spec(input) || nrrd || vdb) {
    if (raw.dims || raw.type || raw.endian == Endian::Big)
      throw InputError(input + ": --dims, --type and big-endian apply only to raw files");
  }
  if (const std::optional<FieldSpec> spec = parse_field_spec(input)) {
    source = std::make_unique<FieldSource>(*spec);
  } else if (vdb) {
    source = std::make_unique<VdbSource>(open_vdb(input));
  } else if (nrrd) {
    if (const std::optional<NrrdDataLayout> d = nrrd_data_layout(input)) {
      const PlainLayout layout{d->data_file, d->offset, d->type, d->dims,
                               (d->endian == Endian::Big) != native_big};
      if (d->gzip)
        source = std::make_unique<GzipRawSource>(layout, "the NRRD header says encoding: gzip");
      else
        source = std::make_unique<RawFileSource>(layout);
      source->spacing = d->spacing;
      source->origin = d->origin;
      source->world = d->world;
    } else {
      source = std::make_unique<InMemorySource>(read_nrrd(input));
    }
  } else {
    struct stat st {};
    if (::stat(input.c_str(), &st) != 0)
      throw IoError("cannot open " + input + ": " + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) throw IoError("cannot open " + input + ": " + std::strerror(EISDIR));
    // Out of core reads the samples twice (the count and extract passes), box by box: a pipe or
    // a character device cannot be read again (a block device, a disk image, can).
    if (S_ISFIFO(st.st_mode) || S_ISCHR(st.st_mode) || S_ISSOCK(st.st_mode))
      throw InputError(input +
                       ": a pipe or device, which can be read only once and in order; an "
                       "out-of-core run reads its input twice: save it to a file, or "
                       "drop --memory");
    const RawLayout r = resolve_raw_layout(input, raw);
    const PlainLayout layout{input, 0, r.type, r.dims, (raw.endian == Endian::Big) != native_big};
    if (ends_with_ci(input, ".gz"))
      source = std::make_unique<GzipRawSource>(layout, "the name ends in .gz");
    else
      source = std::make_unique<RawFileSource>(layout);
  }
  source->name = input;
  if (raw.spacing) source->spacing = *raw.spacing;
  if (raw.origin) {
    source->origin = *raw.origin;
    if (source->world) source->world->origin = *raw.origin;
  }
  return source;
}

VolumeView brick_view(const VolumeSource& source, const Box3& box, const void* data) {
  VolumeView v;
  v.data = data;
  v.type = source.type;
  for (int a = 0; a < 3; ++a) v.dims[a] = box.extent(a);
  v.strides = {1, v.dims[0], v.dims[0] * v.dims[1]};
  v.spacing = source.spacing;
  v.origin = source.origin;
  v.box = box;
  v.global_dims = source.dims;
  v.world = source.world;
  return v;
}

}  // namespace isotile
