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

const char* const kVolumeFilePatterns[21] = {
    "*.raw", "*.gz",  "*.nrrd", "*.nhdr", "*.vdb",  "*.nii",  "*.mha",
    "*.mhd", "*.tif", "*.tiff", "*.mrc",  "*.mrcs", "*.map",  "*.ccp4",
    "*.dcm", "*.ima", "*.DCM",  "*.IMA",  "*.TIF",  "*.TIFF", "*"};
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

std::string format_value(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

// The file's name without the extensions the readers know (".nii.gz" whole).
std::string file_stem(const std::string& file) {
  std::string name = fs::path(file).filename().string();
  if (name.empty()) name = fs::path(file).parent_path().filename().string();  // "dir/"
  auto strip = [&](std::string_view ext) {
    if (name.size() > ext.size() && name.compare(name.size() - ext.size(), ext.size(), ext) == 0) {
      name.resize(name.size() - ext.size());
      return true;
    }
    return false;
  };
  strip(".gz");
  for (std::string_view ext : {".raw", ".nii", ".nrrd", ".nhdr", ".vdb", ".mha", ".mhd", ".tiff",
                               ".tif", ".mrc", ".mrcs", ".map", ".ccp4", ".dcm", ".ima"})
    if (strip(ext)) break;
  return name;
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
  if (!p.iso_auto && !std::isfinite(p.iso))
    throw InputError("iso must be a finite number, or nan for the automatic isovalue");
  o.iso = p.iso;
  o.normals = p.normals;
  return o;
}

}  // namespace

std::string layer_name(const std::string& file, const std::string& series_description,
                       std::string_view method, double iso) {
  std::string base = series_description;
  if (base.empty()) base = file_stem(file);
  if (base.empty()) base = "volume";
  std::string name = base + " " + std::string(method) + " iso" + format_iso(iso);
  for (char& c : name)
    if (c == '.' || c == '/' || c == '\\') c = '_';
  return name;
}

std::string unique_name(const std::string& name,
                        const std::function<bool(const std::string&)>& taken) {
  if (!taken(name)) return name;
  for (int n = 2;; ++n) {
    std::string candidate = name + " (" + std::to_string(n) + ")";
    if (!taken(candidate)) return candidate;
  }
}

IsosurfaceResult run_isosurface(const IsosurfaceParams& p, const std::string& temp_dir,
                                const Progress& progress) {
  const auto t0 = Clock::now();
  auto report = [&](const std::string& stage, double fraction) {
    if (progress) progress(stage, fraction);
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
  const std::string file_name = fs::path(p.file).filename().string();

  IsosurfaceResult r;
  r.backend = std::string(backend_name(backend));
  // A DICOM series is named by its description (a file's name, "00000060.dcm", says nothing).
  std::string series_description, series_uid;
  if (p.file.rfind("field:", 0) != 0 && input_kind(p.file) == InputKind::Dicom) {
    report("reading the DICOM series' headers", 0.01);
    const VolumeHeader h = read_volume_header(p.file, raw);
    series_description = h.series_description;
    series_uid = h.series_uid;
  }
  // No surface: say where the samples lie, and the way out.
  auto no_surface = [&]() {
    std::string m = "no surface at isovalue " + format_value(o.iso) + " in " + p.file;
    if (r.range)
      m += ": the samples range from " + format_value(r.range->first) + " to " +
           format_value(r.range->second) +
           (o.iso > r.range->second ? ", all below it" : ", all at or above it");
    throw InputError(m + "; set iso inside the range, or to nan for the automatic isovalue");
  };
  if (memory == 0) {
    report("reading " + file_name, 0.02);
    const Volume volume = read_volume(p.file, raw);
    if (p.iso_auto) {
      report("choosing the isovalue", 0.25);
      const ValueHistogram h = value_histogram(volume.view());
      r.range = std::pair(h.min, h.max);
      o.iso = otsu_isovalue(h);
    } else {
      r.range = value_range(volume.view());
    }
    // The library's progress (its stage, the fraction of it) onto MeshLab's bar: the
    // extraction from 30% to 60%, the simplification from 60% to 90%.
    // A run goes through several stages (count, extract, Macet's search), each from 0 to 1 and
    // their number not known ahead: stage n fills [1 - 2^-(n-1), 1 - 2^-n) of the span, so
    // the bar only moves forward.
    auto span = [&](double from, double width) {
      return [&report, from, width, stage = Stage::Read, n = 0](const ProgressUpdate& u) mutable {
        if (n == 0 || u.stage != stage) ++n;
        stage = u.stage;
        const double base = 1 - std::ldexp(1.0, 1 - n);
        report(std::string(stage_name(u.stage)),
               from + width * (base + std::ldexp(1.0, -n) * u.fraction));
        return true;
      };
    };
    report("extracting (" + std::string(method_name(o.method)) + ")", 0.3);
    isotile::Progress extracting(span(0.3, 0.3));
    o.progress = &extracting;
    r.mesh = extract(volume.view(), o);
    r.triangles_extracted = r.mesh.triangles.size();
    if (r.mesh.triangles.empty()) no_surface();
    if (p.simplify < 1) {
      report("simplifying", 0.6);
      isotile::Progress simplifying(span(0.6, 0.3));
      SimplifyOptions so;
      so.ratio = p.simplify;
      so.progress = &simplifying;
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
      report("reading the samples' histogram for the isovalue", 0.02);
      const ValueHistogram h = source_histogram(*source, memory);
      r.range = std::pair(h.min, h.max);
      o.iso = otsu_isovalue(h);
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
      report(std::string(stage_name(u.stage)) + " brick " + std::to_string(u.brick + 1) + "/" +
                 std::to_string(u.bricks),
             0.05 + 0.85 * done);
      return true;
    });
    to.progress = &bricks;
    const TiledResult t = extract_tiled(*source, to, mesh_file);
    r.bricks = t.plan.total();
    r.triangles_extracted = p.simplify < 1 ? t.triangles_extracted : t.triangles;
    if (t.faces == 0) {
      if (!r.range) {
        report("reading the samples' range", 0.9);
        const ValueHistogram h = source_histogram(*source, memory);
        r.range = std::pair(h.min, h.max);
      }
      no_surface();
    }
    report("loading the bricks' mesh", 0.9);
    r.mesh = read_mesh(mesh_file);
  }
  report("measuring the triangles", 0.95);
  r.quality = triangle_quality(r.mesh);
  r.iso = o.iso;
  r.layer_name = layer_name(p.file, series_description, method_name(o.method), o.iso);
  r.description = p.file;
  if (!series_description.empty() || !series_uid.empty())
    r.description += ", DICOM series '" + series_description + "' (" + series_uid + ")";
  r.description += ", " + std::string(kMethodNames[p.method]);
  if (o.method == Method::Macet)
    r.description += std::string(" ") + kMacetQualityNames[p.macet_quality];
  r.description += ", isovalue " + format_value(o.iso);
  r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  return r;
}

Mesh run_simplify(const Mesh& mesh, const SimplifyParams& p, SimplifyStats* stats,
                  const Progress& progress) {
  isotile::Progress regions([&](const ProgressUpdate& u) {
    if (progress) progress(std::string(stage_name(u.stage)), u.fraction);
    return true;
  });
  SimplifyOptions o;
  o.progress = &regions;
  o.ratio = p.faces > 0 ? 0 : p.ratio;
  o.faces = p.faces;
  o.max_error = p.max_error;
  o.min_quality = p.min_quality;
  return simplify(mesh, o, stats);
}

}  // namespace isotile::meshlab
