// Mesh files: writers for PLY (binary little-endian by default, ASCII on request), OBJ, binary
// STL and OFF, and a reader for the same formats (used by `isotile quality` and the tests).
//
// Writes are atomic: the mesh goes to a temporary file beside the target, which is renamed over
// the target only once complete and flushed. Any failure (bad directory, full disk, exception)
// removes the temporary file and throws IoError; the target is then untouched.
//
// The reader keeps faces exactly as stored (no welding, no repair), except STL, which stores
// unshared corners: its vertices are welded by exact position so topology can be measured.
// Polygons with more than three corners are kept as quads (4) or fanned into triangles (>4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/progress.h"

namespace isotile {

enum class MeshFormat { Ply, Obj, Stl, Off };

// From the extension (.ply, .obj, .stl, .off; case-insensitive); InputError otherwise.
MeshFormat mesh_format_from_path(const std::filesystem::path& path);

// The format of an output path (by its extension), refusing `ascii` where the format has no text
// form isotile writes (STL is written binary): InputError, before any work.
MeshFormat mesh_output_format(const std::filesystem::path& path, bool ascii);

struct MeshWriteOptions {
  std::optional<MeshFormat> format;  // default: from the extension
  bool ascii = false;                // PLY only: ASCII instead of binary little-endian
  bool write_normals = true;         // when the mesh has normals (PLY, OBJ)
  // Told of the writing (Stage::Write, in vertices and faces, a chunk of 8192 at a time); null:
  // nobody listens. Cancelling throws Cancelled and removes the partial file (AtomicFile).
  Progress* progress = nullptr;
};

void write_mesh(const Mesh& mesh, const std::filesystem::path& path,
                const MeshWriteOptions& options = {});

Mesh read_mesh(const std::filesystem::path& path);

// InputError naming `file` and the vertex where a position is not a finite number (every mesh
// reader's check: such a position is no place).
void check_finite_positions(const std::string& file, const std::vector<Vec3f>& positions);

// Record layouts shared with the tiler's streamed writer, which places every record at its final
// offset brick by brick; using the same pieces keeps its files byte-identical to write_mesh's.
// PLY header; `index64` declares uint64 face indices (meshes past 2^32 - 1 vertices).
std::string ply_header(std::uint64_t vertices, std::uint64_t faces, bool normals, bool ascii,
                       bool index64);
inline constexpr std::size_t kStlHeaderBytes = 84;
inline constexpr std::size_t kStlTriangleBytes = 50;
void stl_header(char* out, std::uint64_t triangles);  // kStlHeaderBytes bytes
// One binary STL triangle record (facet normal from the corners); returns the end.
char* put_stl_triangle(char* p, const Vec3f& a, const Vec3f& b, const Vec3f& c);

}  // namespace isotile
