#include "meshlab_plugin/isosurface_job.h"

#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/mesh/mesh_frame.h"
#include "core/mesh/mesh_io.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/volume_io.h"
#include "tiler/input_options.h"
#include "tiler/source_histogram.h"
#include "tiler/tiled_extract.h"
#include "tiler/volume_source.h"

namespace isotile::meshlab {

const char* const kMethodNames[3] = {"Marching Cubes", "Macet", "Dual Contouring"};
const char* const kMacetQualityNames[2] = {"fast", "max"};
const char* const kDcSolverNames[3] = {"mass point", "particle", "QEF"};
const char* const kDcHermiteNames[2] = {"central", "ENO"};
const char* const kDcVerticesNames[2] = {"patch", "cell"};
const char* const kBackendNames[4] = {"Auto", "CPU", "Geometry shader", "HistoPyramid"};

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// An enum parameter's index, checked (scripts carry indices).
template <std::size_t N>
int checked_choice(int value, const char* const (&names)[N], const char* field) {
  if (value >= 0 && value < static_cast<int>(N)) return value;
  std::string list;
  for (std::size_t i = 0; i < N; ++i) list += (i ? ", " : "") + std::to_string(i) + " " + names[i];
  throw InputError(std::string(field) + " must be one of " + list + "; got " +
                   std::to_string(value));
}

// A folder of its own under `parent` (mkdtemp: mode 0700, a name nobody else chose), removed
// with its contents when it goes out of scope: the brick-by-brick extraction's intermediate file
// goes there, so no file or link another user placed in the shared temporary folder at a name
// this process would write can receive it.
struct PrivateFolder {
  fs::path path;
  explicit PrivateFolder(const fs::path& parent) {
    std::string name = (parent / "isotile-meshlab-XXXXXX").string();
    if (!::mkdtemp(name.data()))
      throw IoError("cannot make a temporary folder in " + parent.string() + ": " +
                    std::strerror(errno));
    path = name;
  }
  ~PrivateFolder() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  PrivateFolder(const PrivateFolder&) = delete;
  PrivateFolder& operator=(const PrivateFolder&) = delete;
};

std::string format_iso(double iso) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", iso);
  return buf;
}

ExtractOptions extract_options(const IsosurfaceParams& p) {
  ExtractOptions o;
  o.method = static_cast<Method>(checked_choice(p.method, kMethodNames, "method"));
  o.quality = checked_choice(p.macet_quality, kMacetQualityNames, "macet_quality") == 1
                  ? MacetQuality::Max
                  : MacetQuality::Fast;
  if (!(p.macet_relax >= 0 && p.macet_relax < 0.5))
    throw InputError("macet_relax must be in [0, 0.5), got " + std::to_string(p.macet_relax));
  if (p.macet_relax > 0 && o.method != Method::Macet)
    throw InputError("macet_relax applies to the Macet method only; set it to 0");
  o.macet_relax = p.macet_relax;
  const int solver = checked_choice(p.dc_solver, kDcSolverNames, "dc_solver");
  o.dc_solver = solver == 1   ? DcSolver::Particle
                : solver == 2 ? DcSolver::Qef
                              : DcSolver::MassPoint;
  o.dc_hermite = checked_choice(p.dc_hermite, kDcHermiteNames, "dc_hermite") == 1
                     ? DcHermite::Eno
                     : DcHermite::Central;
  o.dc_vertices = checked_choice(p.dc_vertices, kDcVerticesNames, "dc_vertices") == 1
                      ? DcVertices::Cell
                      : DcVertices::Patch;
  const int backend = checked_choice(p.backend, kBackendNames, "backend");
  o.backend = backend == 1   ? Backend::Cpu
              : backend == 2 ? Backend::GeometryShader
              : backend == 3 ? Backend::HistoPyramid
                             : Backend::Auto;
  if (!p.iso_auto && !std::isfinite(p.iso)) throw InputError("iso must be a finite number");
  o.iso = p.iso;
  o.normals = p.normals;
  return o;
}

}  // namespace

IsosurfaceResult run_isosurface(const IsosurfaceParams& p, const std::string& temp_dir,
                                const Progress& progress) {
  const auto t0 = Clock::now();
  auto report = [&](int percent, const std::string& what) {
    if (progress) progress(percent, what);
  };
  if (p.file.empty())
    throw InputError(
        "no volume file chosen (the 'file' field is empty): choose one with its '...' button; "
        "MeshLab 2020.09 ignores a path typed into the box");
  if (p.file.rfind("field:", 0) != 0) {
    std::error_code ec;
    // A numbered TIFF pattern (slice_%03d.tif) names no file itself.
    if (!fs::exists(p.file, ec) && p.file.find('%') == std::string::npos)
      throw IoError(p.file + ": no such file");
  }
  if (!(p.simplify > 0 && p.simplify <= 1))
    throw InputError("simplify is the fraction of faces kept, in (0, 1] (1: off); got " +
                     std::to_string(p.simplify));
  ExtractOptions o = extract_options(p);
  const Backend backend = resolve_backend(o);  // InputError naming what is missing
  RawOptions raw = parse_input_text(
      {.dims = p.dims, .type = p.type, .spacing = p.spacing, .origin = "", .endian = p.endian}, "");
  raw.series = p.series;
  const std::uint64_t memory =
      p.memory.empty() || p.memory == "0" ? 0 : parse_memory_size(p.memory);

  IsosurfaceResult r;
  r.backend = std::string(backend_name(backend));
  if (memory == 0) {
    report(5, "reading " + p.file);
    const Volume volume = read_volume(p.file, raw);
    if (p.iso_auto) o.iso = otsu_isovalue(value_histogram(volume.view()));
    report(30, "extracting");
    r.mesh = extract(volume.view(), o);
    r.triangles_extracted = r.mesh.triangles.size();
    if (p.simplify < 1) {
      report(60, "simplifying");
      SimplifyOptions so;
      so.ratio = p.simplify;
      r.mesh = simplify(r.mesh, so);
    }
    // Into the volume's world frame (its orientation), as `isotile extract` writes it.
    apply_frame(mesh_frame(volume.view()), r.mesh);
  } else {
    // Brick by brick within the budget, through the tiler's streamed file: what the CLI's
    // --memory does. MeshLab then holds the whole result.
    const PrivateFolder tmp(temp_dir.empty() ? fs::temp_directory_path() : fs::path(temp_dir));
    const fs::path mesh_file = tmp.path / "bricks.ply";
    auto source = open_volume_source(p.file, raw, memory);
    if (p.iso_auto) {
      report(5, "reading the samples' histogram for the isovalue");
      o.iso = otsu_isovalue(source_histogram(*source, memory));
    }
    TiledOptions to;
    to.frame = mesh_frame(source->origin, source->world);
    to.extract = o;
    to.memory = memory;
    to.format = MeshFormat::Ply;
    to.simplify = p.simplify;
    isotile::Progress bricks([&](const ProgressUpdate& u) {
      const double done = (static_cast<double>(u.brick) + u.fraction) /
                          static_cast<double>(std::max<std::int64_t>(u.bricks, 1));
      report(static_cast<int>(5 + 85 * done), std::string(stage_name(u.stage)) + " " +
                                                  std::to_string(u.brick + 1) + "/" +
                                                  std::to_string(u.bricks));
      return true;
    });
    to.progress = &bricks;
    const TiledResult t = extract_tiled(*source, to, mesh_file);
    r.bricks = t.plan.total();
    r.triangles_extracted = p.simplify < 1 ? t.triangles_extracted : t.triangles;
    report(90, "loading the bricks' mesh");
    r.mesh = read_mesh(mesh_file);
  }
  report(95, "measuring");
  r.quality = triangle_quality(r.mesh);
  r.layer_name = fs::path(p.file).filename().string() + " " + std::string(method_name(o.method)) +
                 " " + format_iso(o.iso);
  r.iso = o.iso;
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return r;
}

Mesh run_simplify(const Mesh& mesh, const SimplifyParams& p, SimplifyStats* stats) {
  SimplifyOptions o;
  o.ratio = p.faces > 0 ? 0 : p.ratio;
  o.faces = p.faces;
  o.max_error = p.max_error;
  o.min_quality = p.min_quality;
  return simplify(mesh, o, stats);
}

}  // namespace isotile::meshlab
