#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"

namespace isotile {

MeshFormat mesh_format_from_path(const std::filesystem::path& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".ply") return MeshFormat::Ply;
  if (ext == ".obj") return MeshFormat::Obj;
  if (ext == ".stl") return MeshFormat::Stl;
  if (ext == ".off") return MeshFormat::Off;
  const std::string what = path.extension().empty()
                               ? "no extension to tell the mesh format by"
                               : "unknown mesh format '" + path.extension().string() + "'";
  throw InputError(path.string() + ": " + what + " (expected .ply, .obj, .stl or .off)");
}

namespace {

// Items per chunk: small enough that the in-flight buffers of all threads stay a few MiB each,
// large enough that task overhead vanishes next to the formatting.
constexpr std::size_t kChunkItems = 8192;

// Formats items [0, count) chunk by chunk on all threads and writes the chunks in order, so the
// file is the same for any thread count while formatting runs in parallel with the writing.
// format(begin, end, out) writes at most max_item_bytes per item from out and returns the end.
// Each chunk written advances `progress` by its items (Stage::Write counts vertices and faces).
template <class Format>
void emit_chunks(AtomicFile& file, Progress* progress, std::size_t count,
                 std::size_t max_item_bytes, const Format& format) {
  if (count == 0) return;
  const std::size_t chunks = (count + kChunkItems - 1) / kChunkItems;
  const std::size_t capacity = std::min(count, kChunkItems) * max_item_bytes;
  if (chunks == 1) {
    auto buffer = std::make_unique_for_overwrite<char[]>(capacity);
    char* end = format(std::size_t{0}, count, buffer.get());
    file.write(buffer.get(), static_cast<std::size_t>(end - buffer.get()));
    progress_advance(progress, static_cast<std::int64_t>(count));
    return;
  }
  // With at most `tokens` chunks between input and output, chunk i and chunk i + tokens are
  // never in flight together, so buffer i % tokens is free when chunk i starts.
  const std::size_t tokens = std::min<std::size_t>(
      chunks, 2 * static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency())));
  struct Buffer {
    std::unique_ptr<char[]> data;
    std::size_t size = 0;
  };
  std::vector<Buffer> buffers(tokens);
  std::size_t next = 0;
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, std::size_t>(tbb::filter_mode::serial_in_order,
                                          [&](tbb::flow_control& fc) -> std::size_t {
                                            if (next == chunks) {
                                              fc.stop();
                                              return 0;
                                            }
                                            return next++;
                                          }) &
          tbb::make_filter<std::size_t, std::size_t>(
              tbb::filter_mode::parallel,
              [&](std::size_t i) {
                Buffer& b = buffers[i % tokens];
                if (!b.data) b.data = std::make_unique_for_overwrite<char[]>(capacity);
                const std::size_t begin = i * kChunkItems;
                const std::size_t end = std::min(count, begin + kChunkItems);
                b.size = static_cast<std::size_t>(format(begin, end, b.data.get()) - b.data.get());
                return i;
              }) &
          tbb::make_filter<std::size_t, void>(
              tbb::filter_mode::serial_in_order, [&](std::size_t i) {
                const Buffer& b = buffers[i % tokens];
                file.write(b.data.get(), b.size);
                progress_advance(progress,
                                 static_cast<std::int64_t>(std::min(count, (i + 1) * kChunkItems) -
                                                           i * kChunkItems));
              }));
}

// Bounds that the buffers are sized by: a shortest float needs at most 15 characters
// ("-1.17549435e-38"), so 24 leaves room; a uint32 needs 10.
constexpr std::size_t kMaxFloatChars = 24;
constexpr std::size_t kMaxUintChars = 10;

char* put_float(char* p, float v) {
  return std::to_chars(p, p + kMaxFloatChars, v).ptr;
}

// Values up to 2^32 (a 1-based OBJ index) fit in kMaxUintChars.
char* put_uint(char* p, std::uint64_t v) {
  return std::to_chars(p, p + kMaxUintChars, v).ptr;
}

char* put_text(char* p, const char* s) {
  const std::size_t n = std::strlen(s);
  std::memcpy(p, s, n);
  return p + n;
}

template <class T>
char* put_le(char* p, T v) {
  static_assert(std::is_trivially_copyable_v<T>);
  if constexpr (std::endian::native == std::endian::big) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &v, sizeof(T));
    std::reverse(bytes, bytes + sizeof(T));
    std::memcpy(p, bytes, sizeof(T));
  } else {
    std::memcpy(p, &v, sizeof(T));
  }
  return p + sizeof(T);
}

// A corrupt index would otherwise produce a file that every reader rejects (or crashes on).
void check_mesh(const Mesh& mesh, const std::filesystem::path& path) {
  const std::size_t nv = mesh.positions.size();
  if (!mesh.normals.empty() && mesh.normals.size() != nv) {
    throw InputError("cannot write " + path.string() + ": the mesh has " +
                     std::to_string(mesh.normals.size()) + " normals for " + std::to_string(nv) +
                     " vertices");
  }
  try {
    check_face_indices(mesh);
    // A NaN or infinite position is no place; every reader refuses it, so none is written.
    check_finite_positions("the mesh", mesh.positions);
  } catch (const InputError& e) {
    throw InputError("cannot write " + path.string() + ": " + e.what());
  }
}

bool use_normals(const Mesh& mesh, const MeshWriteOptions& options) {
  return options.write_normals && !mesh.normals.empty();
}

void write_ply(const Mesh& mesh, AtomicFile& file, const MeshWriteOptions& options,
               Progress* progress) {
  const bool normals = use_normals(mesh, options);
  const std::string header =
      ply_header(mesh.positions.size(), mesh.triangles.size() + mesh.quads.size(), normals,
                 options.ascii, false);
  file.write(header.data(), header.size());

  const auto& pos = mesh.positions;
  const auto& nrm = mesh.normals;
  const auto& tris = mesh.triangles;
  const auto& quads = mesh.quads;
  if (options.ascii) {
    emit_chunks(file, progress, pos.size(), 6 * (kMaxFloatChars + 1),
                [&](std::size_t b, std::size_t e, char* p) {
                  for (std::size_t i = b; i < e; ++i) {
                    p = put_float(p, pos[i][0]);
                    *p++ = ' ';
                    p = put_float(p, pos[i][1]);
                    *p++ = ' ';
                    p = put_float(p, pos[i][2]);
                    if (normals) {
                      for (float c : nrm[i]) {
                        *p++ = ' ';
                        p = put_float(p, c);
                      }
                    }
                    *p++ = '\n';
                  }
                  return p;
                });
    emit_chunks(file, progress, tris.size(), 2 + 3 * (kMaxUintChars + 1),
                [&](std::size_t b, std::size_t e, char* p) {
                  for (std::size_t i = b; i < e; ++i) {
                    *p++ = '3';
                    for (std::uint32_t v : tris[i]) {
                      *p++ = ' ';
                      p = put_uint(p, v);
                    }
                    *p++ = '\n';
                  }
                  return p;
                });
    emit_chunks(file, progress, quads.size(), 2 + 4 * (kMaxUintChars + 1),
                [&](std::size_t b, std::size_t e, char* p) {
                  for (std::size_t i = b; i < e; ++i) {
                    *p++ = '4';
                    for (std::uint32_t v : quads[i]) {
                      *p++ = ' ';
                      p = put_uint(p, v);
                    }
                    *p++ = '\n';
                  }
                  return p;
                });
    return;
  }

  if (!normals && std::endian::native == std::endian::little) {
    // Vec3f is exactly three packed floats, which is the PLY vertex record here.
    static_assert(sizeof(Vec3f) == 12);
    for (std::size_t b = 0; b < pos.size(); b += 64 * kChunkItems) {
      const std::size_t e = std::min(pos.size(), b + 64 * kChunkItems);
      file.write(pos.data() + b, (e - b) * sizeof(Vec3f));
      progress_advance(progress, static_cast<std::int64_t>(e - b));
    }
  } else {
    emit_chunks(file, progress, pos.size(), 24, [&](std::size_t b, std::size_t e, char* p) {
      for (std::size_t i = b; i < e; ++i) {
        for (float c : pos[i]) p = put_le(p, c);
        if (normals) {
          for (float c : nrm[i]) p = put_le(p, c);
        }
      }
      return p;
    });
  }
  emit_chunks(file, progress, tris.size(), 13, [&](std::size_t b, std::size_t e, char* p) {
    for (std::size_t i = b; i < e; ++i) {
      *p++ = 3;
      for (std::uint32_t v : tris[i]) p = put_le(p, v);
    }
    return p;
  });
  emit_chunks(file, progress, quads.size(), 17, [&](std::size_t b, std::size_t e, char* p) {
    for (std::size_t i = b; i < e; ++i) {
      *p++ = 4;
      for (std::uint32_t v : quads[i]) p = put_le(p, v);
    }
    return p;
  });
}

void write_obj(const Mesh& mesh, AtomicFile& file, const MeshWriteOptions& options,
               Progress* progress) {
  const bool normals = use_normals(mesh, options);
  static const char kHeader[] = "# written by isotile\n";
  file.write(kHeader, sizeof(kHeader) - 1);
  const auto& pos = mesh.positions;
  const auto& nrm = mesh.normals;
  emit_chunks(file, progress, pos.size(), 2 * (3 + 3 * (kMaxFloatChars + 1)),
              [&](std::size_t b, std::size_t e, char* p) {
                for (std::size_t i = b; i < e; ++i) {
                  *p++ = 'v';
                  for (float c : pos[i]) {
                    *p++ = ' ';
                    p = put_float(p, c);
                  }
                  *p++ = '\n';
                  if (normals) {
                    p = put_text(p, "vn");
                    for (float c : nrm[i]) {
                      *p++ = ' ';
                      p = put_float(p, c);
                    }
                    *p++ = '\n';
                  }
                }
                return p;
              });
  auto faces = [&](const auto& list) {
    constexpr std::size_t corners = std::tuple_size_v<std::decay_t<decltype(list[0])>>;
    emit_chunks(file, progress, list.size(), 2 + corners * (2 * kMaxUintChars + 3),
                [&](std::size_t b, std::size_t e, char* p) {
                  for (std::size_t i = b; i < e; ++i) {
                    *p++ = 'f';
                    for (std::uint32_t v : list[i]) {
                      *p++ = ' ';
                      // OBJ counts from 1; the uint64 keeps index 2^32-1 from wrapping.
                      const std::uint64_t one_based = std::uint64_t{v} + 1;
                      p = put_uint(p, one_based);
                      if (normals) {
                        *p++ = '/';
                        *p++ = '/';
                        p = put_uint(p, one_based);
                      }
                    }
                    *p++ = '\n';
                  }
                  return p;
                });
  };
  faces(mesh.triangles);
  faces(mesh.quads);
}

void write_off(const Mesh& mesh, AtomicFile& file, Progress* progress) {
  std::string header = "OFF\n" + std::to_string(mesh.positions.size()) + " " +
                       std::to_string(mesh.triangles.size() + mesh.quads.size()) + " 0\n";
  file.write(header.data(), header.size());
  const auto& pos = mesh.positions;
  emit_chunks(file, progress, pos.size(), 3 * (kMaxFloatChars + 1),
              [&](std::size_t b, std::size_t e, char* p) {
                for (std::size_t i = b; i < e; ++i) {
                  p = put_float(p, pos[i][0]);
                  *p++ = ' ';
                  p = put_float(p, pos[i][1]);
                  *p++ = ' ';
                  p = put_float(p, pos[i][2]);
                  *p++ = '\n';
                }
                return p;
              });
  auto faces = [&](const auto& list, char count) {
    emit_chunks(file, progress, list.size(), 2 + 4 * (kMaxUintChars + 1),
                [&](std::size_t b, std::size_t e, char* p) {
                  for (std::size_t i = b; i < e; ++i) {
                    *p++ = count;
                    for (std::uint32_t v : list[i]) {
                      *p++ = ' ';
                      p = put_uint(p, v);
                    }
                    *p++ = '\n';
                  }
                  return p;
                });
  };
  faces(mesh.triangles, '3');
  faces(mesh.quads, '4');
}

}  // namespace

char* put_stl_triangle(char* p, const Vec3f& a, const Vec3f& b, const Vec3f& c) {
  // The stored normal is recomputed from the corners: per-vertex normals are not facet normals.
  const double u[3] = {double{b[0]} - a[0], double{b[1]} - a[1], double{b[2]} - a[2]};
  const double v[3] = {double{c[0]} - a[0], double{c[1]} - a[1], double{c[2]} - a[2]};
  double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  for (double& x : n) x = len > 0 && std::isfinite(len) ? x / len : 0.0;
  for (double x : n) p = put_le(p, static_cast<float>(x));
  for (float x : a) p = put_le(p, x);
  for (float x : b) p = put_le(p, x);
  for (float x : c) p = put_le(p, x);
  return put_le(p, std::uint16_t{0});
}

void stl_header(char* out, std::uint64_t triangles) {
  std::memset(out, ' ', 80);
  // Must not start with "solid", which readers take for ASCII STL.
  std::memcpy(out, "binary STL written by isotile", 29);
  put_le(out + 80, static_cast<std::uint32_t>(triangles));
}

std::string ply_header(std::uint64_t vertices, std::uint64_t faces, bool normals, bool ascii,
                       bool index64) {
  std::string header = "ply\nformat ";
  header += ascii ? "ascii" : "binary_little_endian";
  header += " 1.0\ncomment written by isotile\nelement vertex ";
  header += std::to_string(vertices);
  header += "\nproperty float x\nproperty float y\nproperty float z\n";
  if (normals) header += "property float nx\nproperty float ny\nproperty float nz\n";
  header += "element face ";
  header += std::to_string(faces);
  header += index64 ? "\nproperty list uchar uint64 vertex_indices\nend_header\n"
                    : "\nproperty list uchar uint vertex_indices\nend_header\n";
  return header;
}

namespace {

void write_stl(const Mesh& mesh, AtomicFile& file, Progress* progress) {
  const std::uint64_t count =
      std::uint64_t{mesh.triangles.size()} + 2 * std::uint64_t{mesh.quads.size()};
  char header[kStlHeaderBytes];
  stl_header(header, count);
  file.write(header, sizeof(header));
  const auto& pos = mesh.positions;
  const auto& tris = mesh.triangles;
  const auto& quads = mesh.quads;
  emit_chunks(file, progress, tris.size(), 50, [&](std::size_t b, std::size_t e, char* p) {
    for (std::size_t i = b; i < e; ++i) {
      p = put_stl_triangle(p, pos[tris[i][0]], pos[tris[i][1]], pos[tris[i][2]]);
    }
    return p;
  });
  emit_chunks(file, progress, quads.size(), 100, [&](std::size_t b, std::size_t e, char* p) {
    for (std::size_t i = b; i < e; ++i)
      for (const Tri& t : split_quad(pos, quads[i]).triangles)
        p = put_stl_triangle(p, pos[t[0]], pos[t[1]], pos[t[2]]);
    return p;
  });
}

MeshFormat text_form_checked(MeshFormat format, bool ascii) {
  // A format outside the enum (a cast from a number) wrote an empty file, reported as written.
  if (format != MeshFormat::Ply && format != MeshFormat::Obj && format != MeshFormat::Stl &&
      format != MeshFormat::Off)
    throw InputError("unknown mesh format " + std::to_string(static_cast<int>(format)));
  if (format == MeshFormat::Stl && ascii)
    throw InputError("--ascii writes PLY as text; STL is written binary only");
  return format;
}

}  // namespace

MeshFormat mesh_output_format(const std::filesystem::path& path, bool ascii) {
  return text_form_checked(mesh_format_from_path(path), ascii);
}

void write_mesh(const Mesh& mesh, const std::filesystem::path& path,
                const MeshWriteOptions& options) {
  const MeshFormat format = text_form_checked(
      options.format ? *options.format : mesh_format_from_path(path), options.ascii);
  check_mesh(mesh, path);
  if (format == MeshFormat::Stl) {
    const std::uint64_t count =
        std::uint64_t{mesh.triangles.size()} + 2 * std::uint64_t{mesh.quads.size()};
    if (count > std::numeric_limits<std::uint32_t>::max()) {
      throw CapacityError("cannot write " + path.string() + ": " + std::to_string(count) +
                          " triangles exceed the 2^32-1 that binary STL can count; use PLY");
    }
  }
  AtomicFile file(path);
  // In items: vertices (none in STL) and faces.
  Progress* const progress = options.progress;
  progress_begin(progress, Stage::Write,
                 static_cast<std::int64_t>((format == MeshFormat::Stl ? 0 : mesh.positions.size()) +
                                           mesh.triangles.size() + mesh.quads.size()));
  switch (format) {
    case MeshFormat::Ply:
      write_ply(mesh, file, options, progress);
      break;
    case MeshFormat::Obj:
      write_obj(mesh, file, options, progress);
      break;
    case MeshFormat::Stl:
      write_stl(mesh, file, progress);
      break;
    case MeshFormat::Off:
      write_off(mesh, file, progress);
      break;
  }
  file.commit();
}

}  // namespace isotile
