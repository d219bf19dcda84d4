#include "tests/fuzz/fuzz_targets.h"

#include <teem/nrrd.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "core/errors.h"
#include "core/mesh/mesh_io.h"
#include "core/volume/volume_io.h"

namespace isotile::fuzz {

namespace {

namespace fs = std::filesystem;

void remove_work_dir() {
  std::error_code ec;
  fs::remove_all(work_dir(), ec);
}

// Writes the file with stdio so the targets do not depend on the code under test.
void write_file(const fs::path& path, const std::uint8_t* data, std::size_t size) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) throw std::runtime_error("fuzz: cannot create " + path.string());
  const bool ok = (size == 0 || std::fwrite(data, 1, size, f) == size);
  if (std::fclose(f) != 0 || !ok) throw std::runtime_error("fuzz: cannot write " + path.string());
}

// Removes what one call wrote, also when the reader throws; a crash leaves it for reproduction.
class Files {
 public:
  fs::path add(const std::string& name, const std::uint8_t* data, std::size_t size) {
    fs::path p = work_dir() / name;
    paths_.push_back(p);
    write_file(p, data, size);
    return p;
  }
  ~Files() {
    std::error_code ec;
    for (const fs::path& p : paths_) fs::remove(p, ec);
  }

 private:
  std::vector<fs::path> paths_;
};

[[noreturn]] void violated(const char* target, const std::string& what) {
  throw InvariantViolation(std::string(target) + ": " + what);
}

std::string dims_text(const Index3& d) {
  return std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
}

void check_finite_samples(const char* target, const Volume& volume) {
  const std::int64_t n = volume.sample_count();
  if (volume.type() == ScalarType::Float32) {
    const float* p = volume.data<float>();
    for (std::int64_t i = 0; i < n; ++i)
      if (!std::isfinite(p[i])) violated(target, "sample " + std::to_string(i) + " is not finite");
  } else if (volume.type() == ScalarType::Float64) {
    const double* p = volume.data<double>();
    for (std::int64_t i = 0; i < n; ++i)
      if (!std::isfinite(p[i])) violated(target, "sample " + std::to_string(i) + " is not finite");
  }
}

// Positive dims, byte size = dims * sample size (computed without overflow), storage present,
// every floating-point sample finite.
void check_volume(const char* target, const Volume& volume) {
  const Index3& d = volume.dims();
  std::uint64_t bytes = scalar_size(volume.type());
  bool overflow = false;
  for (int a = 0; a < 3; ++a) {
    if (d[a] <= 0) violated(target, "volume has dims " + dims_text(d));
    overflow |= __builtin_mul_overflow(bytes, static_cast<std::uint64_t>(d[a]), &bytes);
  }
  if (overflow || bytes != volume.byte_size())
    violated(target, "volume of " + dims_text(d) + " " + std::string(scalar_name(volume.type())) +
                         " has byte_size " + std::to_string(volume.byte_size()));
  if (volume.bytes() == nullptr) violated(target, "volume has no storage");
  check_finite_samples(target, volume);
}

void check_mesh(const Mesh& mesh) {
  const std::uint64_t nv = mesh.positions.size();
  if (nv > 0xffffffffull) violated("fuzz_mesh", "more than 2^32-1 vertices");
  if (!mesh.normals.empty() && mesh.normals.size() != nv)
    violated("fuzz_mesh", std::to_string(mesh.normals.size()) + " normals for " +
                              std::to_string(nv) + " positions");
  for (std::size_t f = 0; f < mesh.triangles.size(); ++f)
    for (std::uint32_t v : mesh.triangles[f])
      if (v >= nv)
        violated("fuzz_mesh", "triangle " + std::to_string(f) + " references vertex " +
                                  std::to_string(v) + " of " + std::to_string(nv));
  for (std::size_t f = 0; f < mesh.quads.size(); ++f)
    for (std::uint32_t v : mesh.quads[f])
      if (v >= nv)
        violated("fuzz_mesh", "quad " + std::to_string(f) + " references vertex " +
                                  std::to_string(v) + " of " + std::to_string(nv));
}

}  // namespace

const fs::path& work_dir() {
  // Never destroyed, so that remove_work_dir can still use it at exit.
  static const fs::path* const dir = [] {
    auto* d =
        new fs::path(fs::temp_directory_path() / ("isotile_fuzz_" + std::to_string(::getpid())));
    fs::create_directories(*d);
    std::atexit(remove_work_dir);
    return d;
  }();
  return *dir;
}

int fuzz_mesh(const std::uint8_t* data, std::size_t size) {
  const std::uint8_t sel = size > 0 ? data[0] : 0;
  static constexpr const char* kExt[2][4] = {{".ply", ".obj", ".off", ".stl"},
                                             {".PLY", ".OBJ", ".OFF", ".STL"}};
  Files files;
  const fs::path path = files.add(std::string("input") + kExt[(sel >> 2) & 1][sel & 3],
                                  data + (size > 0), size - (size > 0));
  try {
    check_mesh(read_mesh(path));
    return 0;
  } catch (const Error&) {
    return 1;
  }
}

RawLayout raw_layout(int index, ScalarType type, bool gzip) {
  static constexpr Index3 kDims[6] = {{1, 1, 1}, {2, 3, 4},  {4, 4, 4},
                                      {7, 1, 3}, {1, 16, 2}, {5, 4, 3}};
  const std::string ext = gzip ? ".raw.gz" : ".raw";
  RawLayout l;
  switch (index & 7) {
    case 6:  // dims and type from the name
      l.file_name = "fuzz_3x2x2_" + std::string(scalar_name(type)) + ext;
      l.dims = {3, 2, 2};
      break;
    case 7:  // dims from the name, type from the options (which win over the name's)
      l.file_name = "fuzz_2x5x1_float64" + ext;
      l.option_type = type;
      l.dims = {2, 5, 1};
      break;
    default:
      l.file_name = "input" + ext;
      l.option_dims = kDims[index & 7];
      l.option_type = type;
      l.dims = kDims[index & 7];
      break;
  }
  return l;
}

int fuzz_raw(const std::uint8_t* data, std::size_t size) {
  const std::uint8_t sel = size > 0 ? data[0] : 0;
  const bool gzip = sel & 1;
  const auto type = static_cast<ScalarType>((sel >> 2) & 7);
  const RawLayout layout = raw_layout(sel >> 5, type, gzip);
  RawOptions options;
  options.dims = layout.option_dims;
  options.type = layout.option_type;
  options.endian = (sel & 2) ? Endian::Big : Endian::Little;
  options.spacing = Vec3d{0.5, 1, 2};
  Files files;
  const fs::path path = files.add(layout.file_name, data + (size > 0), size - (size > 0));
  try {
    const Volume v = read_raw(path.string(), options);
    check_volume("fuzz_raw", v);
    if (v.dims() != layout.dims || v.type() != type)
      violated("fuzz_raw", "read " + dims_text(v.dims()) + " " +
                               std::string(scalar_name(v.type())) + ", expected " +
                               dims_text(layout.dims) + " " + std::string(scalar_name(type)));
    if (v.spacing() != *options.spacing) violated("fuzz_raw", "spacing differs from the options");
    return 0;
  } catch (const Error&) {
    return 1;
  }
}

int fuzz_nrrd(const std::uint8_t* data, std::size_t size) {
  // teem warns on stderr about, e.g., data after the end; thousands of such lines help no one.
  nrrdStateVerboseIO = 0;
  const std::uint8_t sel = size > 0 ? data[0] : 0;
  const std::string_view body(reinterpret_cast<const char*>(data) + (size > 0), size - (size > 0));
  const auto* bytes = reinterpret_cast<const std::uint8_t*>(body.data());
  Files files;
  fs::path path;
  if (sel & 1) {
    const std::size_t split = body.find("\n\n");
    const std::size_t header = split == std::string_view::npos ? body.size() : split + 1;
    path = files.add("input.nhdr", bytes, header);
    if (split != std::string_view::npos)
      files.add("data.bin", bytes + split + 2, body.size() - split - 2);
  } else {
    path = files.add("input.nrrd", bytes, body.size());
  }
  try {
    check_volume("fuzz_nrrd", read_nrrd(path.string()));
    return 0;
  } catch (const Error&) {
    return 1;
  }
}

int fuzz_vdb(const std::uint8_t* data, std::size_t size) {
  Files files;
  const fs::path path = files.add("input.vdb", data, size);
  try {
    const Volume v = read_vdb(path.string());
    check_volume("fuzz_vdb", v);
    if (v.type() != ScalarType::Float32 && v.type() != ScalarType::Float64)
      violated("fuzz_vdb", "volume of type " + std::string(scalar_name(v.type())));
    return 0;
  } catch (const Error&) {
    return 1;
  }
}

int fuzz_image(const std::uint8_t* data, std::size_t size) {
  static const char* const kNames[] = {"input.mrc", "input.nii", "input.mha",    "input.map",
                                       "input.dcm", "input.tif", "input.nii.gz", "input.map.gz"};
  const std::uint8_t sel = size > 0 ? data[0] : 0;
  Files files;
  const fs::path path = files.add(kNames[sel & 7], data + (size > 0), size - (size > 0));
  try {
    check_volume("fuzz_image", read_volume(path.string()));
    return 0;
  } catch (const Error&) {
    return 1;
  }
}

}  // namespace isotile::fuzz
