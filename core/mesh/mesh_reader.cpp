// Every count read from a file is checked against the bytes that remain before anything is
// allocated or looped over, and every read is bounds-checked: the reader must survive any bytes.
#include <fcntl.h>
#include <locale.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/errors.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/polygon_triangulation.h"

namespace isotile {

namespace {

constexpr std::uint64_t kMaxVertices = std::numeric_limits<std::uint32_t>::max();

std::vector<char> read_file(const std::filesystem::path& path) {
  auto fail = [&](const char* what, int err) {
    throw IoError(std::string(what) + " " + path.string() + ": " + std::strerror(err));
  };
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail("cannot open", errno);
  struct FdCloser {
    int fd;
    ~FdCloser() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) fail("cannot read", errno);
  if (S_ISDIR(st.st_mode)) fail("cannot read", EISDIR);
  // One byte beyond the size lets the read that sees the end happen without growing the buffer;
  // reading to the end rather than trusting st_size also copes with pipes and changing files.
  std::vector<char> data(S_ISREG(st.st_mode) ? static_cast<std::size_t>(st.st_size) + 1 : 1 << 16);
  std::size_t size = 0;
  for (;;) {
    if (size == data.size()) data.resize(2 * data.size());
    const ssize_t n = ::read(fd, data.data() + size, data.size() - size);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("cannot read", errno);
    }
    if (n == 0) break;
    size += static_cast<std::size_t>(n);
  }
  data.resize(size);
  return data;
}

class Reader {
 public:
  explicit Reader(std::string name) : name_(std::move(name)) {}
  [[noreturn]] void fail(const std::string& what) const { throw InputError(name_ + ": " + what); }
  const std::string& name() const { return name_; }

 private:
  std::string name_;
};

bool is_space(char c) {
  return c == ' ' || c == '\n' || c == '\r' || c == '\t' || c == '\v' || c == '\f';
}

// A line ends at LF, CR LF or a lone CR (classic Mac OS files: read with LF alone, the rest of a
// `v` line was skipped, which was the whole file, and an OBJ gave one vertex and no face, exit 0).
bool is_eol(char c) {
  return c == '\n' || c == '\r';
}

// Whitespace-separated tokens with line tracking, for the text formats.
class Text {
 public:
  Text(const char* begin, const char* end, bool hash_comments)
      : p_(begin), end_(end), comments_(hash_comments) {}

  // The next token, crossing line ends (and comment lines); empty at the end of the text.
  std::string_view token() {
    for (;;) {
      while (p_ < end_ && is_space(*p_)) {
        if (*p_ == '\n' || (*p_ == '\r' && (p_ + 1 == end_ || p_[1] != '\n'))) ++line_;
        ++p_;
      }
      if (comments_ && p_ < end_ && *p_ == '#') {
        skip_line();
        continue;
      }
      return take();
    }
  }

  // The next token on the current line; empty when the line (or a trailing comment) ends.
  std::string_view line_token() {
    while (p_ < end_ && !is_eol(*p_) && is_space(*p_)) ++p_;
    if (p_ == end_ || is_eol(*p_) || (comments_ && *p_ == '#')) return {};
    return take();
  }

  void skip_line() {
    while (p_ < end_ && !is_eol(*p_)) ++p_;
    if (p_ == end_) return;
    if (*p_ == '\r' && p_ + 1 < end_ && p_[1] == '\n') ++p_;
    ++p_;
    ++line_;
  }

  std::size_t line() const { return line_; }
  std::size_t remaining() const { return static_cast<std::size_t>(end_ - p_); }

 private:
  // Where `#` starts comments it also ends a token: `f 1 2 3# note` is a face of three corners.
  std::string_view take() {
    const char* b = p_;
    while (p_ < end_ && !is_space(*p_) && !(comments_ && *p_ == '#')) ++p_;
    return {b, static_cast<std::size_t>(p_ - b)};
  }

  const char* p_;
  const char* end_;
  bool comments_;
  std::size_t line_ = 1;
};

// Rounds like IEEE conversion, including overflow to infinity, which a plain cast leaves
// undefined for values beyond the float range.
float to_float(double d) {
  constexpr double kMax = std::numeric_limits<float>::max();
  // Halfway between FLT_MAX and 2^128: from here on, rounding to nearest gives infinity.
  constexpr double kOverflow = 0x1.ffffffp127;
  const double a = std::fabs(d);
  if (a > kMax) {
    const float big =
        a >= kOverflow ? std::numeric_limits<float>::infinity() : std::numeric_limits<float>::max();
    return d < 0 ? -big : big;
  }
  return static_cast<float>(d);
}

template <class T>
bool parse_number(std::string_view s, T& out) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  if (s.empty() || s[0] == '+' || s[0] == ' ') return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

// A real number in text. Past double's range from_chars reports an error and no value; like a
// float past float's range, such a number is taken as IEEE conversion rounds it: below the range
// 0 (of its sign; "1e-400" was a bad number where "1e-320" read as 0), above it infinity (refused
// later as no finite position, naming the vertex).
bool parse_real(std::string_view s, double& out) {
  if (!s.empty() && s[0] == '+') s.remove_prefix(1);
  if (s.empty() || s[0] == '+' || s[0] == ' ') return false;
  const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  if (ptr != s.data() + s.size()) return false;
  if (ec == std::errc()) return true;
  if (ec != std::errc::result_out_of_range) return false;
  // The text is a well-formed number (from_chars took all of it) past double's range: which way
  // it left the range, strtold_l tells (in the C locale, whatever the process's).
  static const locale_t c_locale = ::newlocale(LC_ALL_MASK, "C", locale_t{});
  const std::string copy(s);
  const bool tiny = std::fabs(::strtold_l(copy.c_str(), nullptr, c_locale)) < 1;
  const bool negative = s[0] == '-';
  out = tiny ? (negative ? -0.0 : 0.0)
             : (negative ? -std::numeric_limits<double>::infinity()
                         : std::numeric_limits<double>::infinity());
  return true;
}

// A coordinate in text: read as a double and rounded to float as IEEE conversion does, so that
// a value below float's range becomes 0 (or a subnormal) as the PLY reader's doubles do, where
// from_chars into a float calls it out of range ("1e-50" was a bad number in OBJ, 0 in PLY).
bool parse_float(std::string_view s, float& out) {
  double d;
  if (!parse_real(s, d)) return false;
  out = to_float(d);
  return true;
}

std::string quoted(std::string_view s) {
  constexpr std::size_t kMax = 40;
  std::string out = "'";
  for (char c : s.substr(0, kMax)) {
    const auto u = static_cast<unsigned char>(c);
    out += (u >= 32 && u < 127) ? c : '?';
  }
  if (s.size() > kMax) out += "...";
  return out + "'";
}

std::string vertex_error(std::uint64_t face, std::int64_t vertex, std::uint64_t count,
                         const char* what = "face") {
  return std::string(what) + " " + std::to_string(face) + " references vertex " +
         std::to_string(vertex) + " but there are " + std::to_string(count) + " vertices";
}

// A file's faces: triangles, quads (kept), and polygons of more than four corners, which become
// triangles by ear clipping (polygon_triangulation.h) once every position is known (a PLY's faces
// may come before its vertices); until then they hold the places of their n - 2 triangles.
class Faces {
 public:
  // Ear clipping takes time growing with the square of a polygon's corners: 65,536 take seconds,
  // and a file's one polygon of millions would take hours. No mesh tool writes such a face.
  static constexpr std::size_t kMaxCorners = 65536;

  explicit Faces(const Reader& reader) : reader_(reader) {}

  void add(Mesh& mesh, const std::uint32_t* c, std::size_t n) {
    if (n > kMaxCorners)
      reader_.fail("a face of " + std::to_string(n) + " corners (polygons of more than " +
                   std::to_string(kMaxCorners) + " are not read)");
    if (n == 3) {
      mesh.triangles.push_back({c[0], c[1], c[2]});
    } else if (n == 4) {
      mesh.quads.push_back({c[0], c[1], c[2], c[3]});
    } else {
      at_.push_back(mesh.triangles.size());
      start_.push_back(corners_.size());
      corners_.insert(corners_.end(), c, c + n);
      mesh.triangles.resize(mesh.triangles.size() + n - 2);
    }
  }
  // Call once the positions are read and the indices checked.
  void triangulate(Mesh& mesh) const {
    for (std::size_t p = 0; p < at_.size(); ++p) {
      const std::size_t end = p + 1 < at_.size() ? start_[p + 1] : corners_.size();
      triangulate_polygon(mesh.positions, corners_.data() + start_[p], end - start_[p],
                          mesh.triangles.data() + at_[p]);
    }
  }

 private:
  const Reader& reader_;
  std::vector<std::size_t> at_;     // each polygon's first triangle
  std::vector<std::size_t> start_;  // each polygon's first corner in corners_
  std::vector<std::uint32_t> corners_;
};

// Ends a run of a triangle strip; no vertex can carry this index (a mesh has fewer than 2^32 - 1).
constexpr std::uint32_t kStripRestart = std::numeric_limits<std::uint32_t>::max();

// The triangles of strips (Stanford's `tristrips` element: runs ended by -1): every other one
// turned round so that all face one way, as OpenGL draws strips. Triangles with a corner twice
// are the joins strips use to turn corners, not faces, and are left out.
void add_strips(Mesh& mesh, const std::uint32_t* c, std::size_t n) {
  std::size_t start = 0;
  for (std::size_t i = 0; i <= n; ++i) {
    if (i < n && c[i] != kStripRestart) continue;
    for (std::size_t k = start; k + 2 < i; ++k) {
      const Tri t =
          (k - start) % 2 == 0 ? Tri{c[k], c[k + 1], c[k + 2]} : Tri{c[k + 1], c[k], c[k + 2]};
      if (t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) mesh.triangles.push_back(t);
    }
    start = i + 1;
  }
}

// ---------------------------------------------------------------------------------------------
// PLY

// I64 and U64 are not in the PLY specification, but isotile's tiler writes uint64 face indices
// for meshes past 2^32 - 1 vertices, and other writers use both.
enum class PlyType { I8, U8, I16, U16, I32, U32, I64, U64, F32, F64 };

std::optional<PlyType> ply_type(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::I8;
  if (s == "uchar" || s == "uint8") return PlyType::U8;
  if (s == "short" || s == "int16") return PlyType::I16;
  if (s == "ushort" || s == "uint16") return PlyType::U16;
  if (s == "int" || s == "int32") return PlyType::I32;
  if (s == "uint" || s == "uint32") return PlyType::U32;
  if (s == "int64") return PlyType::I64;
  if (s == "uint64") return PlyType::U64;
  if (s == "float" || s == "float32") return PlyType::F32;
  if (s == "double" || s == "float64") return PlyType::F64;
  return std::nullopt;
}

std::size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::I8:
    case PlyType::U8:
      return 1;
    case PlyType::I16:
    case PlyType::U16:
      return 2;
    case PlyType::I32:
    case PlyType::U32:
    case PlyType::F32:
      return 4;
    case PlyType::I64:
    case PlyType::U64:
    case PlyType::F64:
      return 8;
  }
  return 0;
}

bool ply_integer(PlyType t) {
  return t != PlyType::F32 && t != PlyType::F64;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::F32;  // of the value, or of the list entries
  bool list = false;
  PlyType count_type = PlyType::U8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;

  // Bytes of the smallest binary record (every list empty); 0 when there are no properties.
  std::uint64_t min_binary_size() const {
    std::uint64_t n = 0;
    for (const auto& p : properties) n += ply_size(p.list ? p.count_type : p.type);
    return n;
  }
  bool fixed_size() const {
    return std::none_of(properties.begin(), properties.end(), [](auto& p) { return p.list; });
  }
  int find(std::string_view prop) const {
    for (std::size_t i = 0; i < properties.size(); ++i) {
      if (properties[i].name == prop) return static_cast<int>(i);
    }
    return -1;
  }
};

enum class PlyFormat { Ascii, Little, Big };

template <class T>
T load(const unsigned char* p, bool swap) {
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, p, sizeof(T));
  if (swap) std::reverse(bytes, bytes + sizeof(T));
  T v;
  std::memcpy(&v, bytes, sizeof(T));
  return v;
}

float load_float(PlyType t, const unsigned char* p, bool swap) {
  switch (t) {
    case PlyType::I8:
      return static_cast<float>(load<std::int8_t>(p, swap));
    case PlyType::U8:
      return static_cast<float>(load<std::uint8_t>(p, swap));
    case PlyType::I16:
      return static_cast<float>(load<std::int16_t>(p, swap));
    case PlyType::U16:
      return static_cast<float>(load<std::uint16_t>(p, swap));
    case PlyType::I32:
      return static_cast<float>(load<std::int32_t>(p, swap));
    case PlyType::U32:
      return static_cast<float>(load<std::uint32_t>(p, swap));
    case PlyType::I64:
      return static_cast<float>(load<std::int64_t>(p, swap));
    case PlyType::U64:
      return static_cast<float>(load<std::uint64_t>(p, swap));
    case PlyType::F32:
      return load<float>(p, swap);
    case PlyType::F64:
      return to_float(load<double>(p, swap));
  }
  return 0;
}

// Integer types only (the header parser rejects float counts and indices).
std::int64_t load_int(PlyType t, const unsigned char* p, bool swap) {
  switch (t) {
    case PlyType::I8:
      return load<std::int8_t>(p, swap);
    case PlyType::U8:
      return load<std::uint8_t>(p, swap);
    case PlyType::I16:
      return load<std::int16_t>(p, swap);
    case PlyType::U16:
      return load<std::uint16_t>(p, swap);
    case PlyType::I32:
      return load<std::int32_t>(p, swap);
    case PlyType::U32:
      return load<std::uint32_t>(p, swap);
    case PlyType::I64:
      return load<std::int64_t>(p, swap);
    case PlyType::U64:
      // Past int64's range is no index or count a file can hold; kept positive so that the
      // callers' range checks name it as too large, not as negative.
      return static_cast<std::int64_t>(std::min<std::uint64_t>(
          load<std::uint64_t>(p, swap), std::numeric_limits<std::int64_t>::max()));
    default:
      return 0;
  }
}

class PlyReader : Reader {
 public:
  PlyReader(std::string name, const std::vector<char>& data)
      : Reader(std::move(name)),
        begin_(reinterpret_cast<const unsigned char*>(data.data())),
        end_(begin_ + data.size()) {}

  Mesh read() {
    parse_header();
    check_elements();
    std::uint64_t vertex_count = 0;
    for (const auto& e : elements_) {
      if (e.name == "vertex") vertex_count = e.count;
    }
    Mesh mesh;
    for (const auto& e : elements_) {
      if (e.name == "vertex") {
        read_vertices(e, mesh);
      } else if (e.name == "face" || e.name == "tristrips") {
        read_faces(e, vertex_count, mesh);
      } else {
        skip_element(e);
      }
    }
    // Data past the last element: its counts say less than the file holds (a count cut short
    // would otherwise drop the rest without a word).
    if (format_ == PlyFormat::Ascii) {
      Text t = ascii_text();
      if (const std::string_view extra = t.token(); !extra.empty())
        fail("line " + std::to_string(lines_before_ + t.line()) + ": " + quoted(extra) +
             " after the last element's records (the header's counts say less than the file "
             "holds)");
    } else if (pos_ != end_) {
      fail(std::to_string(end_ - pos_) +
           " bytes after the last element's records (the header's counts say less than the file "
           "holds)");
    }
    faces_.triangulate(mesh);
    return mesh;
  }

 private:
  void parse_header() {
    const char* text = reinterpret_cast<const char*>(begin_);
    const char* text_end = reinterpret_cast<const char*>(end_);
    std::size_t line = 0;
    const char* p = text;
    bool have_format = false, done = false;
    while (!done) {
      if (p == text_end) fail("PLY header has no end_header line");
      const char* nl = static_cast<const char*>(std::memchr(p, '\n', text_end - p));
      if (!nl) fail("PLY header has no end_header line");
      ++line;
      Text words(p, nl, false);
      p = nl + 1;
      const std::string_view kw = words.token();
      auto where = [&] { return "PLY header line " + std::to_string(line) + ": "; };
      if (line == 1) {
        if (kw != "ply" || !words.token().empty()) fail("not a PLY file (no 'ply' first line)");
        continue;
      }
      if (kw.empty() || kw == "comment" || kw == "obj_info") continue;
      if (kw == "format") {
        const std::string_view f = words.token();
        if (f == "ascii") {
          format_ = PlyFormat::Ascii;
        } else if (f == "binary_little_endian") {
          format_ = PlyFormat::Little;
        } else if (f == "binary_big_endian") {
          format_ = PlyFormat::Big;
        } else {
          fail(where() + "unknown format " + quoted(f));
        }
        have_format = true;
      } else if (kw == "element") {
        PlyElement e;
        e.name = std::string(words.token());
        if (e.name.empty() || !parse_number(words.token(), e.count)) {
          fail(where() + "expected 'element NAME COUNT'");
        }
        for (const auto& other : elements_) {
          if (other.name == e.name &&
              (e.name == "vertex" || e.name == "face" || e.name == "tristrips")) {
            fail(where() + "second '" + e.name + "' element");
          }
        }
        elements_.push_back(std::move(e));
      } else if (kw == "property") {
        if (elements_.empty()) fail(where() + "property before any element");
        PlyProperty prop;
        std::string_view t = words.token();
        if (t == "list") {
          prop.list = true;
          const std::string_view ct = words.token();
          const auto count_type = ply_type(ct);
          if (!count_type) fail(where() + "unknown type " + quoted(ct));
          if (!ply_integer(*count_type)) fail(where() + "list count type must be an integer");
          prop.count_type = *count_type;
          t = words.token();
        }
        const auto type = ply_type(t);
        if (!type) fail(where() + "unknown type " + quoted(t));
        prop.type = *type;
        prop.name = std::string(words.token());
        if (prop.name.empty()) fail(where() + "property without a name");
        // Which of two same-named properties holds the value is anyone's guess (readers differ).
        if (elements_.back().find(prop.name) >= 0)
          fail(where() + "element '" + elements_.back().name + "' has a second property " +
               quoted(std::string_view(prop.name)));
        elements_.back().properties.push_back(std::move(prop));
      } else if (kw == "end_header") {
        done = true;
      } else {
        fail(where() + "unexpected " + quoted(kw));
      }
    }
    if (!have_format) fail("PLY header has no format line");
    pos_ = reinterpret_cast<const unsigned char*>(p);
    lines_before_ = line;
    swap_ = format_ != PlyFormat::Ascii &&
            (format_ == PlyFormat::Big) != (std::endian::native == std::endian::big);
  }

  // Elements that hold a mesh under a name this reader does not read are refused, not skipped:
  // `element Vertex` and `element Face` (PLY's names are case-sensitive) gave an empty mesh with
  // exit 0, and so did faces in an element of another name.
  void check_elements() const {
    const bool vertices = std::any_of(elements_.begin(), elements_.end(),
                                      [](const PlyElement& e) { return e.name == "vertex"; });
    for (const auto& e : elements_) {
      if (e.name == "vertex" || e.name == "face" || e.name == "tristrips") continue;
      if (!vertices && e.find("x") >= 0 && e.find("y") >= 0 && e.find("z") >= 0)
        fail("element '" + e.name +
             "' has x, y and z, but vertices are read from the element named 'vertex' (PLY's "
             "names are case-sensitive), and the file has none");
      for (const char* list : {"vertex_indices", "vertex_index"}) {
        const int k = e.find(list);
        if (k >= 0 && e.properties[k].list)
          fail("element '" + e.name + "' lists " + list +
               ", but faces are read from elements named 'face' or 'tristrips' (PLY's names are "
               "case-sensitive)");
      }
    }
  }

  std::uint64_t remaining() const { return static_cast<std::uint64_t>(end_ - pos_); }

  [[noreturn]] void truncated(const PlyElement& e, std::uint64_t index) const {
    fail("file ends in " + e.name + " " + std::to_string(index) + " of " + std::to_string(e.count));
  }

  // Makes sure `count` records of at least `min_size` bytes (binary) or `min_size` tokens
  // (ASCII, each one at least one byte) can fit in what is left.
  void check_fits(const PlyElement& e, std::uint64_t min_size) const {
    if (min_size == 0) return;
    if (e.count > remaining() / min_size) {
      fail("element '" + e.name + "' declares " + std::to_string(e.count) +
           " records but the file has only " + std::to_string(remaining()) + " bytes left");
    }
  }

  std::uint64_t min_size(const PlyElement& e) const {
    return format_ == PlyFormat::Ascii ? e.properties.size() : e.min_binary_size();
  }

  // ASCII helpers.
  Text ascii_text() const {
    return Text(reinterpret_cast<const char*>(pos_), reinterpret_cast<const char*>(end_), false);
  }
  void ascii_done(const Text& t) {
    pos_ = end_ - t.remaining();
    lines_before_ += t.line() - 1;
  }

  std::string_view ascii_token(Text& t, const PlyElement& e, std::uint64_t index) {
    const std::string_view s = t.token();
    if (s.empty()) truncated(e, index);
    if (record_line_ == 0) record_line_ = t.line();
    return s;
  }

  // An ASCII record is one line: a header that names fewer properties than the lines hold (or
  // more) read the values into the wrong places, and only a total that came out uneven was
  // noticed (three lines of `0 0 0 1` were four vertices of three, exit 0).
  void end_record(Text& t, const PlyElement& e, std::uint64_t index) {
    const std::size_t first = record_line_;
    record_line_ = 0;
    auto where = [&](std::size_t line) {
      return "line " + std::to_string(lines_before_ + line) + ": " + e.name + " " +
             std::to_string(index);
    };
    if (first != 0 && t.line() != first)
      fail(where(first) +
           " has fewer values than the header's properties for it (its record "
           "runs on into the next line)");
    if (const std::string_view extra = t.line_token(); !extra.empty())
      fail(where(t.line()) + " has more values than the header's properties for it (" +
           quoted(extra) + " is left over)");
  }
  [[noreturn]] void bad_number(const Text& t, std::string_view s) const {
    fail("line " + std::to_string(lines_before_ + t.line()) + ": bad number " + quoted(s));
  }
  float ascii_float(Text& t, const PlyElement& e, std::uint64_t index, PlyType type) {
    const std::string_view s = ascii_token(t, e, index);
    if (type == PlyType::F32) {
      float f;
      if (!parse_float(s, f)) bad_number(t, s);
      return f;
    }
    double d;
    if (!parse_real(s, d)) bad_number(t, s);
    return to_float(d);
  }
  std::int64_t ascii_int(Text& t, const PlyElement& e, std::uint64_t index) {
    const std::string_view s = ascii_token(t, e, index);
    std::int64_t v;
    if (!parse_number(s, v)) bad_number(t, s);
    return v;
  }

  // Binary helpers.
  void need(std::uint64_t bytes, const PlyElement& e, std::uint64_t index) const {
    if (bytes > remaining()) truncated(e, index);
  }

  // The list length, checked to be non-negative and to fit in the file.
  std::uint64_t list_count(const PlyProperty& p, const PlyElement& e, std::uint64_t index,
                           Text* text) {
    std::int64_t n;
    if (text) {
      n = ascii_int(*text, e, index);
    } else {
      need(ply_size(p.count_type), e, index);
      n = load_int(p.count_type, pos_, swap_);
      pos_ += ply_size(p.count_type);
    }
    if (n < 0) {
      fail(e.name + " " + std::to_string(index) + ": negative list length " + std::to_string(n));
    }
    const std::uint64_t per = text ? 1 : ply_size(p.type);
    const std::uint64_t left = text ? text->remaining() : remaining();
    if (static_cast<std::uint64_t>(n) > left / per) truncated(e, index);
    return static_cast<std::uint64_t>(n);
  }

  void skip_property(const PlyProperty& p, const PlyElement& e, std::uint64_t index, Text* text) {
    const std::uint64_t n = p.list ? list_count(p, e, index, text) : 1;
    if (text) {
      for (std::uint64_t i = 0; i < n; ++i) ascii_token(*text, e, index);
    } else {
      need(n * ply_size(p.type), e, index);
      pos_ += n * ply_size(p.type);
    }
  }

  void skip_element(const PlyElement& e) {
    const std::uint64_t min = min_size(e);
    check_fits(e, min);
    if (min == 0) return;
    if (format_ != PlyFormat::Ascii && e.fixed_size()) {
      pos_ += e.count * min;
      return;
    }
    std::optional<Text> text;
    if (format_ == PlyFormat::Ascii) text.emplace(ascii_text());
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (const auto& p : e.properties) skip_property(p, e, i, text ? &*text : nullptr);
      if (text) end_record(*text, e, i);
    }
    if (text) ascii_done(*text);
  }

  void read_vertices(const PlyElement& e, Mesh& mesh) {
    const int xyz[3] = {e.find("x"), e.find("y"), e.find("z")};
    const int nxyz[3] = {e.find("nx"), e.find("ny"), e.find("nz")};
    if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail("vertex element has no x, y and z");
    const bool normals = nxyz[0] >= 0 && nxyz[1] >= 0 && nxyz[2] >= 0;
    for (int i = 0; i < 3; ++i) {
      if (e.properties[xyz[i]].list || (normals && e.properties[nxyz[i]].list)) {
        fail("vertex coordinates and normals must not be lists");
      }
    }
    check_fits(e, std::max<std::uint64_t>(min_size(e), 1));
    if (e.count > kMaxVertices) {
      throw CapacityError(name() + ": " + std::to_string(e.count) +
                          " vertices exceed the 2^32-1 an in-memory mesh can index");
    }
    mesh.positions.resize(e.count);
    if (normals) mesh.normals.resize(e.count);

    // Which output each property feeds: 0-2 position, 3-5 normal, -1 none.
    std::vector<int> target(e.properties.size(), -1);
    for (int i = 0; i < 3; ++i) {
      target[xyz[i]] = i;
      if (normals) target[nxyz[i]] = 3 + i;
    }
    auto store = [&](std::uint64_t v, int slot, float value) {
      if (slot < 3) {
        mesh.positions[v][slot] = value;
      } else {
        mesh.normals[v][slot - 3] = value;
      }
    };

    if (format_ == PlyFormat::Ascii) {
      Text t = ascii_text();
      for (std::uint64_t v = 0; v < e.count; ++v) {
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
          const PlyProperty& p = e.properties[k];
          if (target[k] < 0) {
            skip_property(p, e, v, &t);
          } else if (ply_integer(p.type)) {
            store(v, target[k], static_cast<float>(ascii_int(t, e, v)));
          } else {
            store(v, target[k], ascii_float(t, e, v, p.type));
          }
        }
        end_record(t, e, v);
      }
      ascii_done(t);
      return;
    }

    if (e.fixed_size()) {
      const std::uint64_t record = e.min_binary_size();
      // What our writer produces: copy straight through.
      if (!swap_ && !normals && record == 12 && e.properties.size() == 3 && xyz[0] == 0 &&
          xyz[1] == 1 && xyz[2] == 2 &&
          std::all_of(e.properties.begin(), e.properties.end(),
                      [](auto& p) { return p.type == PlyType::F32; })) {
        if (e.count > 0) std::memcpy(mesh.positions.data(), pos_, e.count * record);
        pos_ += e.count * record;
        return;
      }
      std::vector<std::pair<std::size_t, int>> fields;  // offset, target
      std::vector<PlyType> types;
      std::size_t offset = 0;
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        if (target[k] >= 0) {
          fields.emplace_back(offset, target[k]);
          types.push_back(e.properties[k].type);
        }
        offset += ply_size(e.properties[k].type);
      }
      for (std::uint64_t v = 0; v < e.count; ++v) {
        for (std::size_t f = 0; f < fields.size(); ++f) {
          store(v, fields[f].second, load_float(types[f], pos_ + fields[f].first, swap_));
        }
        pos_ += record;
      }
      return;
    }
    for (std::uint64_t v = 0; v < e.count; ++v) {
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        if (target[k] < 0) {
          skip_property(p, e, v, nullptr);
        } else {
          need(ply_size(p.type), e, v);
          store(v, target[k], load_float(p.type, pos_, swap_));
          pos_ += ply_size(p.type);
        }
      }
    }
  }

  // A `face` element's polygons, or a `tristrips` element's strips.
  void read_faces(const PlyElement& e, std::uint64_t vertex_count, Mesh& mesh) {
    const bool strips = e.name == "tristrips";
    int index_prop = e.find("vertex_indices");
    if (index_prop < 0) index_prop = e.find("vertex_index");
    if (index_prop < 0) fail(e.name + " element has no vertex_indices property");
    const PlyProperty& ip = e.properties[index_prop];
    if (!ip.list) fail(e.name + " property vertex_indices is not a list");
    if (!ply_integer(ip.type)) fail(e.name + " vertex indices must be integers");
    const std::uint64_t min = std::max<std::uint64_t>(min_size(e), 1);
    check_fits(e, min);
    // A face of three corners is the smallest there can be; reserve what will certainly fit.
    const std::uint64_t likely = std::min<std::uint64_t>(e.count, remaining() / (min + 2));
    mesh.triangles.reserve(likely);

    std::optional<Text> text;
    if (format_ == PlyFormat::Ascii) text.emplace(ascii_text());
    Text* t = text ? &*text : nullptr;
    const std::size_t isize = ply_size(ip.type);
    std::vector<std::uint32_t> corners;
    for (std::uint64_t f = 0; f < e.count; ++f) {
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        if (static_cast<int>(k) != index_prop) {
          skip_property(p, e, f, t);
          continue;
        }
        const std::uint64_t n = list_count(p, e, f, t);
        if (n < 3 && !strips) {
          fail("face " + std::to_string(f) + " has " + std::to_string(n) +
               " corners (at least 3 needed)");
        }
        corners.resize(n);
        for (std::uint64_t c = 0; c < n; ++c) {
          std::int64_t v;
          if (t) {
            v = ascii_int(*t, e, f);
          } else {
            v = load_int(p.type, pos_, swap_);
            pos_ += isize;
          }
          if (strips && v == -1) {
            corners[c] = kStripRestart;
            continue;
          }
          if (v < 0 || static_cast<std::uint64_t>(v) >= vertex_count) {
            fail(vertex_error(f, v, vertex_count, strips ? "strip" : "face"));
          }
          corners[c] = static_cast<std::uint32_t>(v);
        }
        if (strips) {
          add_strips(mesh, corners.data(), n);
        } else {
          faces_.add(mesh, corners.data(), n);
        }
      }
      if (t) end_record(*t, e, f);
    }
    if (t) ascii_done(*t);
  }

  const unsigned char* begin_;
  const unsigned char* end_;
  const unsigned char* pos_ = nullptr;
  std::vector<PlyElement> elements_;
  Faces faces_{*this};
  PlyFormat format_ = PlyFormat::Ascii;
  bool swap_ = false;
  std::size_t lines_before_ = 0;  // text lines before the current Text starts
  std::size_t record_line_ = 0;   // the Text's line of the open ASCII record's first value; 0: none
};

// ---------------------------------------------------------------------------------------------
// OBJ

std::size_t bom(const std::vector<char>& data) {
  return data.size() >= 3 && std::memcmp(data.data(), "\xEF\xBB\xBF", 3) == 0 ? 3 : 0;
}

class ObjReader : Reader {
 public:
  // A UTF-8 byte order mark (Notepad writes one) is skipped: glued to the first keyword it made
  // an unknown one, skipped as OBJ's unknown keywords are, and a first vertex left out shifted
  // every face's corners by one.
  ObjReader(std::string name, const std::vector<char>& data)
      : Reader(std::move(name)), text_(data.data() + bom(data), data.data() + data.size(), true) {}

  Mesh read() {
    Mesh mesh;
    std::vector<Vec3f> normals;
    // Normals are per position in a Mesh; an OBJ's separate normal indices only map onto that
    // when every corner pairs a position with the normal of the same number.
    bool normals_match = true;
    bool any_normal = false;
    std::uint64_t max_normal = 0;
    // Corners stay 0-based and unchecked until all vertices are known: a face may come first.
    std::vector<std::uint64_t> corners;
    std::vector<std::size_t> face_start;
    for (;;) {
      const std::string_view kw = text_.token();
      if (kw.empty()) break;
      if (kw == "v" || kw == "vn") {
        Vec3f p;
        for (float& c : p) c = number();
        (kw == "v" ? mesh.positions : normals).push_back(p);
        if (mesh.positions.size() > kMaxVertices) {
          throw CapacityError(name() + ": more than 2^32-1 vertices");
        }
      } else if (kw == "f" || kw == "fo") {  // `fo`: the face keyword of OBJ's first versions
        face_start.push_back(corners.size());
        for (std::string_view c = value(); !c.empty(); c = value()) {
          const std::size_t s1 = c.find('/');
          const std::uint64_t v = index(c.substr(0, s1), mesh.positions.size());
          corners.push_back(v);
          if (s1 == std::string_view::npos) continue;
          const std::string_view rest = c.substr(s1 + 1);
          const std::size_t s2 = rest.find('/');
          // "v/t" and "v/t/" carry no normal.
          if (s2 == std::string_view::npos || s2 + 1 == rest.size()) continue;
          const std::uint64_t n = index(rest.substr(s2 + 1), normals.size());
          any_normal = true;
          max_normal = std::max(max_normal, n);
          if (n != v) normals_match = false;
        }
        const std::size_t n = corners.size() - face_start.back();
        if (n < 3) {
          fail(at() + "face has " + std::to_string(n) + " corners (at least 3 needed)");
        }
      }
      text_.skip_line();
    }
    if (any_normal && max_normal >= normals.size()) {
      fail("a face references normal " + std::to_string(max_normal + 1) + " but there are " +
           std::to_string(normals.size()) + " normals");
    }
    const std::uint64_t nv = mesh.positions.size();
    std::vector<std::uint32_t> face;
    Faces faces(*this);
    face_start.push_back(corners.size());
    for (std::size_t f = 0; f + 1 < face_start.size(); ++f) {
      face.clear();
      for (std::size_t c = face_start[f]; c < face_start[f + 1]; ++c) {
        if (corners[c] >= nv) fail(vertex_error(f, static_cast<std::int64_t>(corners[c] + 1), nv));
        face.push_back(static_cast<std::uint32_t>(corners[c]));
      }
      faces.add(mesh, face.data(), face.size());
    }
    faces.triangulate(mesh);
    if (normals_match && normals.size() == nv && nv > 0) mesh.normals = std::move(normals);
    return mesh;
  }

 private:
  std::string at() const { return "line " + std::to_string(text_.line()) + ": "; }

  // The statement's next value, on this line or, after a `\` that ends a line (OBJ's line
  // continuation), the next; empty where the statement ends.
  std::string_view value() {
    for (;;) {
      const std::string_view v = text_.line_token();
      if (v != "\\") return v;
      if (const std::string_view more = text_.line_token(); !more.empty())
        fail(at() + "'\\' before " + quoted(more) +
             " (a line continues only after a '\\' at its end)");
      text_.skip_line();
    }
  }

  float number() {
    const std::string_view s = value();
    float f;
    if (!parse_float(s, f)) {
      fail(at() + (s.empty() ? std::string("missing number") : "bad number " + quoted(s)));
    }
    return f;
  }

  // 1-based or negative (relative to what is defined so far) -> 0-based. Positive indices are
  // range-checked later, against the final count.
  std::uint64_t index(std::string_view s, std::uint64_t defined) {
    std::int64_t i;
    if (!parse_number(s, i) || i == 0) fail(at() + "bad index " + quoted(s));
    if (i > 0) return static_cast<std::uint64_t>(i - 1);
    if (static_cast<std::uint64_t>(-(i + 1)) >= defined) {
      fail(at() + "relative index " + std::to_string(i) + " but only " + std::to_string(defined) +
           " defined so far");
    }
    return defined - static_cast<std::uint64_t>(-(i + 1)) - 1;
  }

  Text text_;
};

// ---------------------------------------------------------------------------------------------
// OFF

Mesh read_off(const Reader& r, const std::vector<char>& data) {
  Text t(data.data(), data.data() + data.size(), true);
  auto at = [&] { return "line " + std::to_string(t.line()) + ": "; };
  const std::string_view magic = t.token();
  bool normals = false;
  if (magic == "NOFF" || magic == "CNOFF" || magic == "NCOFF") {
    normals = true;
  } else if (magic != "OFF" && magic != "COFF") {
    r.fail("not an OFF file (first word is " + quoted(magic) + ")");
  }
  // The counts, on one line (after OFF or on the next). Many writers leave out the edge count,
  // which nothing reads: taken from the next line it was the first vertex's x, and the file
  // failed far on with "file ends in face 3".
  std::uint64_t counts[3] = {};
  for (int i = 0; i < 3; ++i) {
    const std::string_view s = i == 0 ? t.token() : t.line_token();
    if (i == 2 && s.empty()) break;
    if (!parse_number(s, counts[i]))
      r.fail(at() + "expected the vertex and face counts (and the edge count) on one line");
  }
  t.skip_line();
  const std::uint64_t nv = counts[0], nf = counts[1];
  // A vertex line holds at least five characters ("0 0 0"), a face line at least seven.
  if (nv > t.remaining() / 5 || nf > t.remaining() / 7 || nv * 5 + nf * 7 > t.remaining()) {
    r.fail("header declares " + std::to_string(nv) + " vertices and " + std::to_string(nf) +
           " faces but the file has only " + std::to_string(t.remaining()) + " bytes left");
  }
  if (nv > kMaxVertices) r.fail("more than 2^32-1 vertices");

  Mesh mesh;
  mesh.positions.resize(nv);
  if (normals) mesh.normals.resize(nv);
  auto number = [&](std::string_view s, const char* what, std::uint64_t i) {
    float f;
    if (!parse_float(s, f)) {
      r.fail(at() + (s.empty() ? "missing coordinate of " : "bad number " + quoted(s) + " in ") +
             what + " " + std::to_string(i));
    }
    return f;
  };
  for (std::uint64_t v = 0; v < nv; ++v) {
    mesh.positions[v][0] = number(t.token(), "vertex", v);
    mesh.positions[v][1] = number(t.line_token(), "vertex", v);
    mesh.positions[v][2] = number(t.line_token(), "vertex", v);
    if (normals) {
      for (float& c : mesh.normals[v]) c = number(t.line_token(), "vertex", v);
    }
    t.skip_line();  // colours and texture coordinates
  }
  std::vector<std::uint32_t> corners;
  Faces faces(r);
  for (std::uint64_t f = 0; f < nf; ++f) {
    const std::string_view s = t.token();
    std::uint64_t n;
    if (!parse_number(s, n)) {
      r.fail(at() + (s.empty() ? std::string("file ends") : "bad corner count " + quoted(s)) +
             " in face " + std::to_string(f));
    }
    if (n < 3) {
      r.fail("face " + std::to_string(f) + " has " + std::to_string(n) +
             " corners (at least 3 needed)");
    }
    if (n > t.remaining() / 2) r.fail(at() + "face " + std::to_string(f) + " is truncated");
    corners.resize(n);
    for (std::uint64_t c = 0; c < n; ++c) {
      const std::string_view w = t.line_token();
      std::int64_t v;
      if (!parse_number(w, v)) {
        r.fail(at() + (w.empty() ? std::string("missing") : "bad") + " vertex index in face " +
               std::to_string(f));
      }
      if (v < 0 || static_cast<std::uint64_t>(v) >= nv) r.fail(vertex_error(f, v, nv));
      corners[c] = static_cast<std::uint32_t>(v);
    }
    faces.add(mesh, corners.data(), n);
    t.skip_line();
  }
  if (const std::string_view extra = t.token(); !extra.empty())
    r.fail(at() + quoted(extra) + " after the last face (the counts line says " +
           std::to_string(nf) + " faces)");
  faces.triangulate(mesh);
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// STL

// Welds corners by exact position, numbering vertices in order of first appearance.
class Welder {
 public:
  explicit Welder(Mesh& mesh, std::uint64_t corners) : mesh_(mesh) {
    std::size_t cap = 1024;
    // Closed meshes have about half as many vertices as triangles; start there and grow.
    while (cap < corners / 3) cap *= 2;
    table_.assign(cap, kEmpty);
  }

  std::uint32_t add(Vec3f p) {
    // -0 and +0 are the same position.
    for (float& c : p) c = c == 0.0f ? 0.0f : c;
    std::size_t i = hash(p) & (table_.size() - 1);
    for (;;) {
      const std::uint32_t v = table_[i];
      if (v == kEmpty) break;
      if (same(mesh_.positions[v], p)) return v;
      i = (i + 1) & (table_.size() - 1);
    }
    if (mesh_.positions.size() >= kMaxVertices) {
      throw CapacityError("more than 2^32-1 distinct STL vertices");
    }
    const auto v = static_cast<std::uint32_t>(mesh_.positions.size());
    mesh_.positions.push_back(p);
    table_[i] = v;
    if (2 * mesh_.positions.size() > table_.size()) grow();
    return v;
  }

 private:
  static constexpr std::uint32_t kEmpty = std::numeric_limits<std::uint32_t>::max();

  // Bitwise, so that NaN coordinates weld too instead of growing a vertex per corner.
  static bool same(const Vec3f& a, const Vec3f& b) { return std::memcmp(&a, &b, 12) == 0; }

  static std::size_t hash(const Vec3f& p) {
    std::uint64_t h = 0x9E3779B97F4A7C15ull;
    for (float c : p) {
      h ^= std::bit_cast<std::uint32_t>(c);
      h *= 0xBF58476D1CE4E5B9ull;
      h ^= h >> 31;
    }
    return static_cast<std::size_t>(h);
  }

  void grow() {
    std::vector<std::uint32_t> bigger(table_.size() * 2, kEmpty);
    const std::size_t mask = bigger.size() - 1;
    for (std::uint32_t v : table_) {
      if (v == kEmpty) continue;
      std::size_t i = hash(mesh_.positions[v]) & mask;
      while (bigger[i] != kEmpty) i = (i + 1) & mask;
      bigger[i] = v;
    }
    table_.swap(bigger);
  }

  Mesh& mesh_;
  std::vector<std::uint32_t> table_;
};

// `text_hint`: what to add to a size error when the file begins as ASCII STL does.
Mesh read_stl_binary(const Reader& r, const std::vector<char>& data,
                     const std::string& text_hint = {}) {
  if (data.size() < 84) r.fail("binary STL shorter than its 84-byte header" + text_hint);
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  const bool swap = std::endian::native == std::endian::big;
  const std::uint64_t count = load<std::uint32_t>(bytes + 80, swap);
  // Exactly: fewer triangles than the file holds would drop the rest without a word.
  if (84 + 50 * count != data.size()) {
    r.fail("binary STL header says " + std::to_string(count) + " triangles (" +
           std::to_string(84 + 50 * count) + " bytes) but the file has " +
           std::to_string(data.size()) + " bytes" + text_hint);
  }
  Mesh mesh;
  mesh.triangles.resize(count);
  Welder weld(mesh, 3 * count);
  for (std::uint64_t t = 0; t < count; ++t) {
    const unsigned char* p = bytes + 84 + 50 * t + 12;  // past the stored normal
    for (int c = 0; c < 3; ++c) {
      Vec3f v;
      for (int k = 0; k < 3; ++k) v[k] = load<float>(p + 12 * c + 4 * k, swap);
      mesh.triangles[t][c] = weld.add(v);
    }
  }
  return mesh;
}

// ASCII STL's keywords in any case: some CAD exporters write "SOLID" and "FACET NORMAL", and
// other readers (MeshLab's, Assimp's) take them.
bool stl_keyword(std::string_view s, std::string_view word) {
  return s.size() == word.size() &&
         std::equal(s.begin(), s.end(), word.begin(), [](char a, char b) {
           return (a >= 'A' && a <= 'Z' ? static_cast<char>(a - 'A' + 'a') : a) == b;
         });
}

Mesh read_stl_ascii(const Reader& r, const std::vector<char>& data) {
  Text t(data.data(), data.data() + data.size(), false);
  auto at = [&] { return "line " + std::to_string(t.line()) + ": "; };
  auto expect = [&](std::string_view word) {
    const std::string_view s = t.token();
    if (!stl_keyword(s, word)) {
      r.fail(at() + "expected '" + std::string(word) + "' but found " +
             (s.empty() ? std::string("the end of the file") : quoted(s)));
    }
  };
  auto number = [&] {
    const std::string_view s = t.token();
    float f;
    if (!parse_float(s, f)) r.fail(at() + "bad number " + quoted(s));
    return f;
  };
  Mesh mesh;
  // An ASCII facet takes well over 100 bytes; this bound only sizes the weld table.
  Welder weld(mesh, data.size() / 40);
  expect("solid");
  t.skip_line();  // the solid's name
  for (;;) {
    const std::string_view kw = t.token();
    if (stl_keyword(kw, "endsolid")) {
      t.skip_line();
      const std::string_view next = t.token();
      if (next.empty()) break;
      if (!stl_keyword(next, "solid")) r.fail(at() + "expected 'solid' but found " + quoted(next));
      t.skip_line();
      continue;
    }
    if (!stl_keyword(kw, "facet")) {
      r.fail(at() + "expected 'facet' or 'endsolid' but found " +
             (kw.empty() ? std::string("the end of the file") : quoted(kw)));
    }
    expect("normal");
    for (int i = 0; i < 3; ++i) number();
    expect("outer");
    expect("loop");
    Tri tri;
    for (auto& c : tri) {
      expect("vertex");
      Vec3f v;
      for (float& x : v) x = number();
      c = weld.add(v);
    }
    expect("endloop");
    expect("endfacet");
    mesh.triangles.push_back(tri);
  }
  return mesh;
}

Mesh read_stl(const Reader& r, const std::vector<char>& data) {
  // Binary files may also begin with "solid", so a size that matches the binary layout wins.
  if (data.size() >= 84) {
    const auto count = load<std::uint32_t>(reinterpret_cast<const unsigned char*>(data.data()) + 80,
                                           std::endian::native == std::endian::big);
    if (84 + 50 * std::uint64_t{count} == data.size()) return read_stl_binary(r, data);
  }
  std::size_t i = 0;
  while (i < data.size() && is_space(data[i])) ++i;
  // Text never holds a NUL byte; a binary STL's header and floats almost always do, so one
  // whose size is off is named as binary, not read as text that ends too soon.
  const void* nul = std::memchr(data.data(), '\0', std::min<std::size_t>(data.size(), 4096));
  const bool solid = data.size() - i >= 5 && stl_keyword({data.data() + i, 5}, "solid") &&
                     (data.size() - i == 5 || is_space(data[i + 5]));
  if (solid && !nul) return read_stl_ascii(r, data);
  // A text file with a stray NUL is named as what it looks like too, not only as binary.
  const std::string hint =
      solid ? "; it begins with 'solid' as ASCII STL does, but holds a NUL byte (at offset " +
                  std::to_string(static_cast<const char*>(nul) - data.data()) +
                  "), which text does not"
            : std::string();
  return read_stl_binary(r, data, hint);
}

}  // namespace

Mesh read_mesh(const std::filesystem::path& path) {
  const MeshFormat format = mesh_format_from_path(path);
  const std::vector<char> data = read_file(path);
  const std::string name = path.string();
  Reader r(name);
  if (data.empty()) r.fail("empty file");
  Mesh mesh;
  switch (format) {
    case MeshFormat::Ply:
      mesh = PlyReader(name, data).read();
      break;
    case MeshFormat::Obj:
      mesh = ObjReader(name, data).read();
      break;
    case MeshFormat::Off:
      mesh = read_off(r, data);
      break;
    case MeshFormat::Stl:
      mesh = read_stl(r, data);
      break;
  }
  // Refused here, naming the file, rather than by whatever reads the mesh next (simplify,
  // render and the intersection test named none).
  check_finite_positions(name, mesh.positions);
  return mesh;
}

void check_finite_positions(const std::string& file, const std::vector<Vec3f>& positions) {
  for (std::size_t v = 0; v < positions.size(); ++v)
    for (const float c : positions[v])
      if (!std::isfinite(c))
        // Readers round doubles and text to float32, so a finite value past float32's range
        // arrives here as infinity too: said so, lest a file's 1e39 be called infinite.
        throw InputError(file + ": vertex " + std::to_string(v) +
                         " has a coordinate that is not a finite number (" + std::to_string(c) +
                         (std::isinf(c) ? ": infinite, or past float32's largest, 3.4e38" : "") +
                         ")");
}

}  // namespace isotile
