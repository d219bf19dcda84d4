// Raw volumes: plain or gzip'd samples, x fastest, dims and type from the options or the name.
#include <fcntl.h>
#include <libdeflate.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <regex>
#include <string>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/volume/volume_io.h"

namespace isotile {

namespace {

// Bounded so one failed read says something promptly and gzread's unsigned length cannot wrap.
constexpr std::size_t kChunkBytes = std::size_t{64} << 20;
// With a Progress: a unit of reading (well under 0.1 s read or inflated on one thread).
constexpr std::size_t kProgressBytes = std::size_t{4} << 20;

struct NameMatch {
  std::string dims[3];
  std::string type;
};

// The NAME_XxYxZ_TYPE.raw[.gz] pattern, without judging whether TYPE is known, so that read_raw
// can say "unknown type" rather than "name has no dims".
std::optional<NameMatch> match_raw_name(const std::string& path) {
  // In any case, as other formats' extensions (V_64X64X64_UINT8.RAW).
  static const std::regex kPattern(R"(^.+_([0-9]+)x([0-9]+)x([0-9]+)_([A-Za-z0-9]+)\.raw(\.gz)?$)",
                                   std::regex::icase);
  const std::string name = std::filesystem::path(path).filename().string();
  std::smatch m;
  if (!std::regex_match(name, m, kPattern)) return std::nullopt;
  NameMatch out;
  for (int a = 0; a < 3; ++a) out.dims[a] = m[a + 1].str();
  out.type = ascii_lower(m[4].str());
  return out;
}

std::optional<std::int64_t> parse_dim(const std::string& s) {
  std::int64_t v = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return v;
}

std::string dims_string(const Index3& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

bool ends_with_gz(const std::string& path) {
  return ends_with_ci(std::filesystem::path(path).filename().string(), ".gz");
}

std::string size_mismatch(const std::string& path, const char* holds, std::uint64_t have,
                          const Index3& dims, ScalarType type, std::uint64_t need) {
  return path + ": " + holds + " " + std::to_string(have) + " bytes but " + dims_string(dims) +
         " " + std::string(scalar_name(type)) + " needs " + std::to_string(need) +
         (have < need ? " (too short)" : " (too long)");
}

template <class U>
void swap_words(std::byte* bytes, std::size_t count) {
  U* words = reinterpret_cast<U*>(bytes);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, std::size_t{1} << 16),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) {
                        if constexpr (sizeof(U) == 2) words[i] = __builtin_bswap16(words[i]);
                        if constexpr (sizeof(U) == 4) words[i] = __builtin_bswap32(words[i]);
                        if constexpr (sizeof(U) == 8) words[i] = __builtin_bswap64(words[i]);
                      }
                    });
}

void byte_swap(Volume& volume) {
  const std::size_t n = static_cast<std::size_t>(volume.sample_count());
  switch (scalar_size(volume.type())) {
    case 2:
      swap_words<std::uint16_t>(volume.bytes(), n);
      break;
    case 4:
      swap_words<std::uint32_t>(volume.bytes(), n);
      break;
    case 8:
      swap_words<std::uint64_t>(volume.bytes(), n);
      break;
    default:
      break;
  }
}

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

// Pipes and other non-regular files, whose size is not known in advance.
void read_stream(const std::string& path, std::FILE* file, Volume& volume, Progress* progress) {
  std::byte* out = volume.bytes();
  const std::size_t need = volume.byte_size();
  std::size_t done = 0;
  while (done < need) {
    const std::size_t want = std::min(progress ? kProgressBytes : kChunkBytes, need - done);
    const std::size_t got = std::fread(out + done, 1, want, file);
    done += got;
    progress_advance(progress, static_cast<std::int64_t>(got));
    if (got < want) {
      if (std::ferror(file)) throw IoError("cannot read " + path + ": " + std::strerror(errno));
      throw InputError(size_mismatch(path, "file holds", done, volume.dims(), volume.type(), need));
    }
  }
  char extra;
  if (std::fread(&extra, 1, 1, file) == 1)
    throw InputError(path + ": file holds more than the " + std::to_string(need) + " bytes " +
                     dims_string(volume.dims()) + " " + std::string(scalar_name(volume.type())) +
                     " needs (too long)");
}

// Slices of a regular file (whose size was checked) read with pread on all threads: one stdio
// stream copies from the page cache and faults the volume's fresh pages in on one thread only.
constexpr std::size_t kSliceBytes = std::size_t{16} << 20;

// Bytes [base + at, base + end) of the open file into out + at.
void read_range(const std::string& path, int fd, std::byte* out, std::size_t at, std::size_t end,
                std::uint64_t base = 0) {
  while (at < end) {
    const ssize_t got = ::pread(fd, out + at, end - at, static_cast<off_t>(base + at));
    if (got < 0) {
      if (errno == EINTR) continue;
      throw IoError("cannot read " + path + ": " + std::strerror(errno));
    }
    if (got == 0) throw IoError("cannot read " + path + ": the file shrank while it was read");
    at += static_cast<std::size_t>(got);
  }
}

void read_regular(const std::string& path, int fd, Volume& volume, Progress* progress) {
  std::byte* out = volume.bytes();
  const std::size_t need = volume.byte_size();
  const std::size_t slice = progress ? kProgressBytes : kSliceBytes;
  const std::size_t slices = (need + slice - 1) / slice;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, slices, 1),
      [&](const tbb::blocked_range<std::size_t>& r) {
        for (std::size_t s = r.begin(); s != r.end(); ++s) {
          progress_check(progress);
          const std::size_t end = std::min(need, (s + 1) * slice);
          read_range(path, fd, out, s * slice, end);
          progress_advance(progress, static_cast<std::int64_t>(end - s * slice));
        }
      },
      tbb::simple_partitioner());
}

struct GzCloser {
  void operator()(gzFile f) const { gzclose_r(f); }
};

[[noreturn]] void throw_gz_error(const std::string& path, gzFile file) {
  int code = Z_OK;
  const char* message = gzerror(file, &code);
  if (code == Z_ERRNO) throw IoError("cannot read " + path + ": " + std::strerror(errno));
  throw InputError(path + ": corrupt gzip data: " + gzerror_text(path, message));
}

using GzFilePtr = std::unique_ptr<gzFile_s, GzCloser>;

GzFilePtr open_gzip(const std::string& path) {
  errno = 0;
  GzFilePtr file(gzopen(path.c_str(), "rb"));
  if (!file)
    throw IoError("cannot open " + path + ": " +
                  (errno ? std::strerror(errno) : "out of memory for zlib state"));
  gzbuffer(file.get(), 1u << 20);
  // zlib would pass a non-gzip file through unchanged; a .gz name that is not gzip is a mistake
  // worth naming rather than a size mismatch further on.
  if (gzdirect(file.get()))
    throw InputError(path + ": not gzip data (the name ends in .gz); rename it or recompress it");
  return file;
}

void read_gzip(const std::string& path, const GzFilePtr& file, Volume& volume, Progress* progress) {
  std::byte* out = volume.bytes();
  const std::size_t need = volume.byte_size();
  std::size_t done = 0;
  while (done < need) {
    const auto want =
        static_cast<unsigned>(std::min(progress ? kProgressBytes : kChunkBytes, need - done));
    const int got = gzread(file.get(), out + done, want);
    if (got < 0) throw_gz_error(path, file.get());
    done += static_cast<std::size_t>(got);
    progress_advance(progress, got);
    if (static_cast<unsigned>(got) < want) {
      // zlib reports a stream cut off mid-way as Z_BUF_ERROR after returning what it had.
      int code = Z_OK;
      const char* message = gzerror(file.get(), &code);
      if (code == Z_BUF_ERROR)
        throw InputError(path + ": truncated gzip data: it ends after " + std::to_string(done) +
                         " of the " + std::to_string(need) + " bytes " +
                         dims_string(volume.dims()) + " " +
                         std::string(scalar_name(volume.type())) + " needs (" +
                         gzerror_text(path, message) + ")");
      if (code != Z_OK) throw_gz_error(path, file.get());
      throw InputError(
          size_mismatch(path, "decompresses to", done, volume.dims(), volume.type(), need));
    }
  }
  // Reading past the end also makes zlib verify the gzip trailer (CRC and length).
  char extra;
  const int got = gzread(file.get(), &extra, 1);
  if (got < 0) throw_gz_error(path, file.get());
  if (got == 1)
    throw InputError(path + ": decompresses to more than the " + std::to_string(need) + " bytes " +
                     dims_string(volume.dims()) + " " + std::string(scalar_name(volume.type())) +
                     " needs (too long)");
  int code = Z_OK;
  const char* message = gzerror(file.get(), &code);
  if (code == Z_BUF_ERROR)
    throw InputError(path + ": truncated gzip data: all " + std::to_string(need) +
                     " bytes are there but the stream's end (CRC and length) is cut off (" +
                     gzerror_text(path, message) + ")");
  if (code != Z_OK) throw_gz_error(path, file.get());
}

// Whole-buffer gzip decompression with libdeflate, about 3.5x faster than zlib's stream (bonsai:
// 12 against 43 ms, docs/benchmarks.md), for files small enough that holding the compressed bytes
// beside the volume for a moment costs little. Above this, zlib streams.
// With a Progress, libdeflate (one call, no progress inside) takes only files it inflates in well
// under 0.1 s; zlib streams larger ones, reporting every kProgressBytes.
constexpr std::uint64_t kWholeGzipMaxBytes = std::uint64_t{1} << 30;
constexpr std::uint64_t kWholeGzipMaxBytesWithProgress = std::uint64_t{8} << 20;

// The gzip file `path`, opened for inflate_whole when it is a regular file of at most
// kWholeGzipMaxBytes that starts with gzip's magic bytes; null otherwise (then zlib opens it and
// judges it, as it did before this path existed).
std::unique_ptr<std::FILE, FileCloser> open_whole_gzip(const std::string& path,
                                                       const struct stat& st, bool progress) {
  if (!S_ISREG(st.st_mode) || st.st_size < 2 ||
      static_cast<std::uint64_t>(st.st_size) >
          (progress ? kWholeGzipMaxBytesWithProgress : kWholeGzipMaxBytes))
    return nullptr;
  std::unique_ptr<std::FILE, FileCloser> file(std::fopen(path.c_str(), "rb"));
  unsigned char magic[2];
  if (!file || ::pread(::fileno(file.get()), magic, 2, 0) != 2 || magic[0] != 0x1f ||
      magic[1] != 0x8b)
    return nullptr;
  return file;
}

// Reads the whole gzip file (of `bytes`; one member or several, as pigz and bgzip write) and
// inflates it into the volume. False when that does not give exactly the volume's bytes, for any
// reason (corrupt, too short or too long, trailing data): zlib then reads the file, and its
// diagnosis names the problem, so every error and every accepted file are those of zlib's stream.
bool inflate_whole(const std::string& path, int fd, std::size_t bytes, Volume& volume) {
  const auto in = std::make_unique_for_overwrite<std::byte[]>(bytes);
  read_range(path, fd, in.get(), 0, bytes);
  std::unique_ptr<libdeflate_decompressor, void (*)(libdeflate_decompressor*)> d(
      libdeflate_alloc_decompressor(), libdeflate_free_decompressor);
  if (!d) return false;
  std::byte* out = volume.bytes();
  const std::size_t need = volume.byte_size();
  std::size_t used = 0, done = 0;
  while (used < bytes) {
    std::size_t member_in = 0, member_out = 0;
    if (libdeflate_gzip_decompress_ex(d.get(), in.get() + used, bytes - used, out + done,
                                      need - done, &member_in, &member_out) != LIBDEFLATE_SUCCESS)
      return false;
    used += member_in;
    done += member_out;
  }
  return done == need;
}

using Layout = RawLayout;

Layout resolve_layout(const std::string& path, const RawOptions& options) {
  std::optional<Index3> dims = options.dims;
  std::optional<ScalarType> type = options.type;
  if (!dims || !type) {
    if (const std::optional<NameMatch> m = match_raw_name(path)) {
      if (!dims) {
        Index3 d{};
        for (int a = 0; a < 3; ++a) {
          const std::optional<std::int64_t> v = parse_dim(m->dims[a]);
          if (!v)
            throw InputError(path + ": dimension " + m->dims[a] +
                             " in the file name is too large; pass --dims X,Y,Z");
          d[a] = *v;
        }
        dims = d;
      }
      if (!type) {
        type = parse_scalar_type(m->type);
        if (!type)
          throw InputError(path + ": unknown sample type '" + m->type +
                           "' in the file name; pass --type T (int8, uint8, int16, uint16, "
                           "int32, uint32, float32 or float64)");
      }
    }
  }
  if (!dims || !type) {
    // Ask for what is missing only: the other was given.
    const std::string missing = !dims && !type ? "dims and sample type are"
                                : !dims        ? "dims are"
                                               : "sample type is";
    const std::string pass = !dims && !type ? "--dims X,Y,Z and --type T"
                             : !dims        ? "--dims X,Y,Z"
                                            : "--type T";
    throw InputError(path + ": the " + missing +
                     " unknown (a raw volume's name is not NAME_XxYxZ_TYPE.raw[.gz]); pass " +
                     pass);
  }
  return {*dims, *type};
}

}  // namespace

RawLayout resolve_raw_layout(const std::string& path, const RawOptions& options) {
  return resolve_layout(path, options);
}

std::optional<RawNameInfo> parse_raw_name(const std::string& path) {
  const std::optional<NameMatch> m = match_raw_name(path);
  if (!m) return std::nullopt;
  RawNameInfo info{};
  for (int a = 0; a < 3; ++a) {
    const std::optional<std::int64_t> d = parse_dim(m->dims[a]);
    if (!d) return std::nullopt;
    info.dims[a] = *d;
  }
  const std::optional<ScalarType> type = parse_scalar_type(m->type);
  if (!type) return std::nullopt;
  info.type = *type;
  return info;
}

std::string gzerror_text(const std::string& opened_as, const char* message) {
  std::string text = message ? message : "unknown zlib error";
  if (text.rfind(opened_as + ": ", 0) == 0)
    text.erase(0, opened_as.size() + 2);
  else if (text.rfind("<fd:", 0) == 0 && text.find(">: ") != std::string::npos)
    text.erase(0, text.find(">: ") + 3);
  return text;
}

void read_plain_data(const PlainData& plain, Volume& volume) {
  const auto read = [](const std::string& file, std::uint64_t offset, std::byte* out,
                       std::size_t bytes) {
    const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw IoError("cannot open " + file + ": " + std::strerror(errno));
    try {
      read_range(file, fd, out, 0, bytes, offset);
    } catch (...) {
      ::close(fd);
      throw;
    }
    ::close(fd);
  };
  if (plain.planes.empty()) {
    read(plain.file, plain.offset, volume.bytes(), volume.byte_size());
  } else {
    const std::size_t plane = volume.byte_size() / plain.planes.size();
    for (std::size_t z = 0; z < plain.planes.size(); ++z)
      read(plain.planes[z].file, plain.planes[z].offset, volume.bytes() + z * plane, plane);
  }
  const bool native_big = std::endian::native == std::endian::big;
  if ((plain.endian == Endian::Big) != native_big) byte_swap(volume);
}

Volume read_raw(const std::string& path, const RawOptions& options) {
  check_raw_overrides(options);
  // Opened before the name is judged, so a mistyped path is reported as missing rather than as
  // lacking --dims.
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw IoError("cannot open " + path + ": " + std::strerror(errno));
  if (S_ISDIR(st.st_mode)) throw IoError("cannot open " + path + ": " + std::strerror(EISDIR));
  const bool gzip = ends_with_gz(path);
  GzFilePtr gz_file;  // zlib's stream, opened unless libdeflate takes the file whole
  std::unique_ptr<std::FILE, FileCloser> whole_gz, plain_file;
  if (gzip) {
    whole_gz = open_whole_gzip(path, st, options.progress != nullptr);
    if (!whole_gz) gz_file = open_gzip(path);
  } else {
    plain_file.reset(std::fopen(path.c_str(), "rb"));
    if (!plain_file) throw IoError("cannot open " + path + ": " + std::strerror(errno));
  }

  const Layout layout = resolve_layout(path, options);
  const std::size_t need = checked_volume_bytes(layout.type, layout.dims);
  // A size check up front avoids allocating gigabytes for a file that cannot fit. Pipes and other
  // non-regular files are checked while reading instead.
  if (!gzip && S_ISREG(st.st_mode) && static_cast<std::uint64_t>(st.st_size) != need)
    throw InputError(size_mismatch(path, "file holds", static_cast<std::uint64_t>(st.st_size),
                                   layout.dims, layout.type, need));

  Volume volume(layout.type, layout.dims, options.spacing.value_or(Vec3d{1, 1, 1}),
                options.origin.value_or(Vec3d{0, 0, 0}));
  Progress* const progress = options.progress;
  progress_begin(progress, Stage::Read, static_cast<std::int64_t>(need));  // in bytes
  if (gzip) {
    if (whole_gz && inflate_whole(path, ::fileno(whole_gz.get()),
                                  static_cast<std::size_t>(st.st_size), volume)) {
      progress_advance(progress, static_cast<std::int64_t>(need));
    } else {
      if (!gz_file) gz_file = open_gzip(path);
      read_gzip(path, gz_file, volume, progress);
    }
  } else if (S_ISREG(st.st_mode)) {
    read_regular(path, ::fileno(plain_file.get()), volume, progress);
  } else {
    read_stream(path, plain_file.get(), volume, progress);
  }
  const bool native_big = std::endian::native == std::endian::big;
  if ((options.endian == Endian::Big) != native_big) byte_swap(volume);
  check_finite(volume.view(), path);
  return volume;
}

}  // namespace isotile
