#include "core/mesh/ply_face_stream.h"

#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <string>

#include "core/errors.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/polygon_triangulation.h"

namespace isotile {

namespace {

bool little_endian_host() {
  const std::uint16_t one = 1;
  unsigned char b;
  std::memcpy(&b, &one, 1);
  return b == 1;
}

}  // namespace

std::optional<PlyFaceStream> PlyFaceStream::open(const std::filesystem::path& path) {
  if (!little_endian_host()) return std::nullopt;
  PlyFaceStream s;
  s.path_ = path;
  // Only a regular file's size bounds the header's counts before anything is sized by them (a
  // FIFO's 152 bytes claiming 1e8 vertices took 1.2 GB before the read found them missing);
  // anything else is read whole, and its counts checked against what came, by read_mesh(). Asked
  // before opening: a FIFO opened here and closed would leave read_mesh() waiting for a writer
  // that has gone.
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) return std::nullopt;
  s.file_.reset(std::fopen(path.c_str(), "rb"));
  if (!s.file_) throw IoError("cannot open " + path.string() + ": " + std::strerror(errno));
  std::FILE* f = s.file_.get();
  // The header, line by line (at most 64 KiB of it).
  std::vector<std::string> lines;
  std::string line;
  std::size_t total = 0;
  for (int c; (c = std::fgetc(f)) != EOF;) {
    if (++total > 65536) return std::nullopt;
    if (c == '\r') continue;
    if (c != '\n') {
      line += static_cast<char>(c);
      continue;
    }
    lines.push_back(line);
    if (line == "end_header") break;
    line.clear();
  }
  if (lines.size() < 3 || lines.front() != "ply" || lines.back() != "end_header")
    return std::nullopt;
  std::uint64_t vertices = 0;
  int props = 0, xyz[3] = {-1, -1, -1};
  enum { None, Vertex, Face, Done } at = None;
  bool binary_le = false, face_list = false;
  std::vector<std::string> vertex_names;
  for (std::size_t i = 1; i + 1 < lines.size(); ++i) {
    std::istringstream in(lines[i]);
    std::string kw;
    in >> kw;
    if (kw == "comment" || kw == "obj_info" || kw.empty()) continue;
    if (kw == "format") {
      std::string fmt, version;
      in >> fmt >> version;
      binary_le = fmt == "binary_little_endian" && version == "1.0";
    } else if (kw == "element") {
      std::string name, digits;
      // Digits only: >> into an unsigned takes "-1" as 2^64 - 1.
      if (!(in >> name >> digits) || digits.empty() || digits.size() > 19 ||
          digits.find_first_not_of("0123456789") != std::string::npos)
        return std::nullopt;
      const std::uint64_t count = std::stoull(digits);
      if (at == None && name == "vertex") {
        at = Vertex;
        vertices = count;
      } else if (at == Vertex && name == "face") {
        at = Face;
        s.faces_ = count;
      } else {
        return std::nullopt;  // another element, or out of order
      }
    } else if (kw == "property") {
      std::string type;
      in >> type;
      if (at == Vertex) {
        std::string name;
        in >> name;
        if (type != "float" && type != "float32") return std::nullopt;
        // A property named twice (x or any other): the full reader names the file's fault.
        if (std::find(vertex_names.begin(), vertex_names.end(), name) != vertex_names.end())
          return std::nullopt;
        vertex_names.push_back(name);
        static const char* const kAxes[3] = {"x", "y", "z"};
        for (int k = 0; k < 3; ++k)
          if (name == kAxes[k]) xyz[k] = props;
        ++props;
      } else if (at == Face && !face_list && type == "list") {
        std::string count_type, index_type, name;
        in >> count_type >> index_type >> name;
        if ((count_type != "uchar" && count_type != "uint8") ||
            (name != "vertex_indices" && name != "vertex_index"))
          return std::nullopt;
        if (index_type == "int" || index_type == "int32") {
          s.index_signed_ = true;
        } else if (index_type == "uint64") {
          s.index_bytes_ = 8;
        } else if (index_type != "uint" && index_type != "uint32") {
          return std::nullopt;
        }
        face_list = true;
      } else {
        return std::nullopt;
      }
    } else {
      return std::nullopt;
    }
  }
  if (!binary_le || at != Face || !face_list || xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)
    return std::nullopt;
  if (vertices > 0xFFFFFFFFull)
    throw CapacityError(path.string() + " has " + std::to_string(vertices) +
                        " vertices; faces are read with 32-bit indices (at most 4294967295)");
  // The counts against the file before anything is sized by them: a header's claim of 3e8
  // vertices took 3.5 GB and seconds before the read found them missing.
  const long header_end = std::ftell(f);
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && header_end >= 0) {
    const std::uint64_t left = size - static_cast<std::uint64_t>(header_end);
    const std::uint64_t record = 4 * static_cast<std::uint64_t>(props);
    if (vertices > left / record)
      throw InputError(path.string() + ": element 'vertex' declares " + std::to_string(vertices) +
                       " records but the file has only " + std::to_string(left) + " bytes left");
    const std::uint64_t face_min = 1 + 3 * static_cast<std::uint64_t>(s.index_bytes_);
    if (s.faces_ > (left - vertices * record) / face_min)
      throw InputError(path.string() + ": element 'face' declares " + std::to_string(s.faces_) +
                       " records but the file has only " +
                       std::to_string(left - vertices * record) + " bytes left");
  }
  // The vertices, a block at a time.
  s.positions_.resize(vertices);
  std::vector<float> block;
  const std::uint64_t per_block = 1 << 16;
  for (std::uint64_t v = 0; v < vertices; v += per_block) {
    const std::uint64_t n = std::min(per_block, vertices - v);
    block.resize(n * props);
    if (std::fread(block.data(), sizeof(float) * props, n, f) != n)
      throw InputError(path.string() + ": the vertices are cut short");
    for (std::uint64_t k = 0; k < n; ++k)
      for (int a = 0; a < 3; ++a) s.positions_[v + k][a] = block[k * props + xyz[a]];
  }
  check_finite_positions(path.string(), s.positions_);  // as read_mesh() does
  if (s.faces_ == 0) s.check_end();                     // next() is not called for no faces
  return s;
}

bool PlyFaceStream::next(std::size_t max_triangles, std::vector<Tri>& out) {
  if (read_ >= faces_) return false;
  std::FILE* f = file_.get();
  const std::uint64_t nv = positions_.size();
  std::uint64_t idx[256];
  unsigned char raw[256 * 8];
  while (read_ < faces_ && out.size() < max_triangles) {
    const int count = std::fgetc(f);
    if (count == EOF) throw InputError(path_.string() + ": the faces are cut short");
    if (count < 3)
      throw InputError(path_.string() + ": face " + std::to_string(read_) + " has " +
                       std::to_string(count) + " corners");
    if (std::fread(raw, index_bytes_, count, f) != static_cast<std::size_t>(count))
      throw InputError(path_.string() + ": the faces are cut short");
    for (int k = 0; k < count; ++k) {
      if (index_bytes_ == 8) {
        std::memcpy(&idx[k], raw + k * 8, 8);
      } else if (index_signed_) {
        std::int32_t v;
        std::memcpy(&v, raw + k * 4, 4);
        idx[k] = v < 0 ? ~std::uint64_t{0} : static_cast<std::uint64_t>(v);
      } else {
        std::uint32_t v;
        std::memcpy(&v, raw + k * 4, 4);
        idx[k] = v;
      }
      if (idx[k] >= nv)
        throw InputError(path_.string() + ": face " + std::to_string(read_) +
                         " references a vertex past the " + std::to_string(nv) + " vertices");
    }
    std::uint32_t corner[256];
    for (int k = 0; k < count; ++k) corner[k] = static_cast<std::uint32_t>(idx[k]);
    // As read_mesh() takes them: a quad's two halves on 0-2, a larger polygon's ears.
    const std::size_t at = out.size();
    out.resize(at + static_cast<std::size_t>(count - 2));
    if (count <= 4) {
      out[at] = {corner[0], corner[1], corner[2]};
      if (count == 4) out[at + 1] = {corner[0], corner[2], corner[3]};
    } else {
      triangulate_polygon(positions_, corner, static_cast<std::size_t>(count), &out[at]);
    }
    ++read_;
  }
  if (read_ == faces_) check_end();
  return true;
}

void PlyFaceStream::check_end() {
  // Data past the last face: the header's counts say less than the file holds, and the rest of
  // the mesh would be left out of the picture without a word (the whole-mesh reader refuses it
  // too).
  if (std::fgetc(file_.get()) != EOF)
    throw InputError(path_.string() +
                     ": data after the last face (the header's counts say less than the file "
                     "holds)");
}

}  // namespace isotile
