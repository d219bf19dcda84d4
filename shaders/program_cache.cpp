#include "program_cache.h"

#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <system_error>
#include <vector>

#include "gl_context.h"

namespace isotile::gl {

namespace {

namespace fs = std::filesystem;

constexpr char kMagic[8] = {'I', 'S', 'O', 'P', 'R', 'G', '0', '1'};

// The header of an entry, before the key and the binary.
struct Header {
  char magic[8];
  std::uint32_t format;  // the driver's binary format
  std::uint32_t reserved;
  std::uint64_t key_bytes, binary_bytes;
  std::uint64_t checksum;  // FNV-1a over the key and the binary
};

std::uint64_t fnv1a(const void* data, std::size_t n, std::uint64_t h = 14695981039346656037ull) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

ProgramCacheCounts& counts() {
  static ProgramCacheCounts c;
  return c;
}

// One note per process when the folder cannot be written.
void note_unwritable(const fs::path& dir, const std::string& why) {
  static bool noted = false;
  if (noted) return;
  noted = true;
  std::fprintf(stderr,
               "isotile: note: the GL program cache %s cannot be written (%s); programs are "
               "compiled on every run\n",
               dir.c_str(), why.c_str());
}

// The device part of every key.
std::string device_key() {
  const DeviceInfo& d = device();
  return d.vendor + "\n" + d.renderer + "\n" + d.version + "\n" + d.glsl_version + "\n";
}

std::string hex(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

}  // namespace

ProgramCacheCounts program_cache_counts() {
  return counts();
}

fs::path program_cache_dir() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x == '/') return fs::path(x) / "isotile";
  if (const char* h = std::getenv("HOME"); h && *h) return fs::path(h) / ".cache" / "isotile";
  return {};
}

bool program_cache_enabled(std::string* why) {
  auto no = [&](const char* reason) {
    if (why) *why = reason;
    return false;
  };
  if (const char* e = std::getenv("ISOTILE_PROGRAM_CACHE"); e && std::string(e) == "off")
    return no("turned off by ISOTILE_PROGRAM_CACHE=off");
  if (device().program_binary_formats <= 0)
    return no("the driver cannot save programs (GL_NUM_PROGRAM_BINARY_FORMATS is 0)");
  if (program_cache_dir().empty()) return no("neither XDG_CACHE_HOME nor HOME is set");
  return true;
}

fs::path program_cache_file(const std::string& key) {
  const std::string full = device_key() + key;
  return program_cache_dir() / (hex(fnv1a(full.data(), full.size())) + ".bin");
}

GLuint load_program(const std::string& key) {
  if (!program_cache_enabled()) return 0;
  const fs::path file = program_cache_file(key);
  std::ifstream in(file, std::ios::binary);
  if (!in) return 0;  // not saved yet
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                std::istreambuf_iterator<char>());
  const std::string full = device_key() + key;
  auto reject = [&] {
    ++counts().rejected;
    return GLuint{0};
  };
  Header h;
  if (bytes.size() < sizeof h) return reject();
  std::memcpy(&h, bytes.data(), sizeof h);
  if (std::memcmp(h.magic, kMagic, sizeof kMagic) != 0 || h.key_bytes != full.size() ||
      h.binary_bytes == 0 || bytes.size() != sizeof h + h.key_bytes + h.binary_bytes)
    return reject();
  const char* stored_key = bytes.data() + sizeof h;
  const char* binary = stored_key + h.key_bytes;
  if (fnv1a(binary, h.binary_bytes, fnv1a(stored_key, h.key_bytes)) != h.checksum ||
      std::memcmp(stored_key, full.data(), full.size()) != 0)
    return reject();
  while (glGetError() != GL_NO_ERROR) {
  }
  const GLuint prog = glCreateProgram();
  glProgramBinary(prog, h.format, binary, static_cast<GLsizei>(h.binary_bytes));
  GLint linked = 0;
  glGetProgramiv(prog, GL_LINK_STATUS, &linked);
  if (glGetError() != GL_NO_ERROR || !linked) {
    glDeleteProgram(prog);
    return reject();
  }
  ++counts().loaded;
  return prog;
}

void store_program(const std::string& key, GLuint prog) {
  if (!program_cache_enabled()) return;
  GLint length = 0;
  glGetProgramiv(prog, GL_PROGRAM_BINARY_LENGTH, &length);
  if (length <= 0) return;
  std::vector<char> binary(static_cast<std::size_t>(length));
  GLenum format = 0;
  GLsizei got = 0;
  glGetProgramBinary(prog, length, &got, &format, binary.data());
  if (glGetError() != GL_NO_ERROR || got <= 0) return;
  binary.resize(static_cast<std::size_t>(got));
  const std::string full = device_key() + key;
  Header h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.format = format;
  h.key_bytes = full.size();
  h.binary_bytes = binary.size();
  h.checksum = fnv1a(binary.data(), binary.size(), fnv1a(full.data(), full.size()));

  const fs::path dir = program_cache_dir();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return note_unwritable(dir, ec.message());
  // A name no other process or thread uses, in the same folder, then renamed over the entry:
  // readers see the old entry, no entry, or the whole new one.
  static std::atomic<unsigned> serial{0};
  std::random_device rd;
  const fs::path file = program_cache_file(key);
  std::string tmp_name = ".";  // appended, not concatenated: GCC 12's -Wrestrict
  tmp_name += file.filename().string();
  for (const std::string& part :
       {std::to_string(getpid()), std::to_string(serial++), hex(rd()), std::string("tmp")}) {
    tmp_name += '.';
    tmp_name += part;
  }
  const fs::path tmp = dir / tmp_name;
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (out) {
      out.write(reinterpret_cast<const char*>(&h), sizeof h);
      out.write(full.data(), static_cast<std::streamsize>(full.size()));
      out.write(binary.data(), static_cast<std::streamsize>(binary.size()));
      out.close();
    }
    if (!out) {
      fs::remove(tmp, ec);
      return note_unwritable(dir, "writing " + tmp.filename().string() + " failed");
    }
  }
  fs::rename(tmp, file, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    return note_unwritable(dir, ec.message());
  }
}

void count_compiled_program() {
  ++counts().compiled;
}

void count_program_seconds(double seconds) {
  counts().seconds += seconds;
}

}  // namespace isotile::gl
