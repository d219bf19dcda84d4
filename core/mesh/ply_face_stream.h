// Reads a binary little-endian PLY's faces in pieces, its vertices whole: what drawing a mesh too
// large for memory needs (`extract --memory ... --render`, `isotile render`). The vertex
// positions (12 bytes each) are held; the faces (the larger part of a mesh) are read piece by
// piece from the file and never held whole.
//
// Takes the layout isotile's writers and most tools write: a `vertex` element whose properties
// are all float and include x, y and z, then a `face` element whose only property is a list of
// vertex indices (uchar count; int, uint or uint64 indices), and nothing after it, in a regular
// file. open() returns nothing for any other PLY (ASCII, big-endian, double coordinates, more
// elements) and for a FIFO or device, which read_mesh() reads whole instead.
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include "core/mesh/mesh.h"

namespace isotile {

class PlyFaceStream {
 public:
  // Reads the header and the vertices; nothing when the file is not of the layout above (or
  // not a PLY). Throws IoError when it cannot be read, InputError when it is cut short.
  static std::optional<PlyFaceStream> open(const std::filesystem::path& path);

  const std::vector<Vec3f>& positions() const { return positions_; }
  std::uint64_t faces() const { return faces_; }

  // Appends the triangles of the next faces to `out` until it holds at least `max_triangles`
  // or the faces end (a quad gives 0 1 2 and 0 2 3, a larger polygon its ears, as read_mesh()
  // cuts it: polygon_triangulation.h); false when no face was left. Throws InputError for an index
  // past the vertices, a face of fewer than three corners, a file cut short, or data after the last
  // face.
  bool next(std::size_t max_triangles, std::vector<Tri>& out);

 private:
  void check_end();  // throws InputError where the file goes on after the last face

  struct Closer {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  std::filesystem::path path_;
  std::unique_ptr<std::FILE, Closer> file_;
  std::vector<Vec3f> positions_;
  std::uint64_t faces_ = 0, read_ = 0;
  int index_bytes_ = 4;
  bool index_signed_ = false;
};

}  // namespace isotile
