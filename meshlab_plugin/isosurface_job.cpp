#include "meshlab_plugin/isosurface_job.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string_view>
#include <utility>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "core/file_names.h"
#include "core/mesh/mesh_io.h"
#include "core/progress.h"
#include "tiler/input_options.h"
#include "tiler/option_names.h"
#include "tiler/pipeline.h"
#include "tiler/source_histogram.h"

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

// The system's temporary folder, as an isotile error where there is none (TMPDIR naming a
// folder that does not exist: Qt's tempPath() is then empty, and the standard library's
// filesystem_error named neither the folder nor TMPDIR).
fs::path temporary_folder() {
  std::error_code ec;
  fs::path dir = fs::temp_directory_path(ec);
  if (ec) {
    const char* env = std::getenv("TMPDIR");
    throw IoError("no temporary folder for the bricks' mesh" +
                  (env ? std::string(" (TMPDIR is '") + env + "')" : std::string()) + ": " +
                  ec.message() + "; set TMPDIR to a folder that exists, or 'Memory' to 0");
  }
  return dir;
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
  // Any case: scanners and older tools write SLICE.DCM, EMBRYO.TIF.
  auto strip = [&](std::string_view ext) {
    if (name.size() > ext.size() && ends_with_ci(name, ext)) {
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

// Another method's fields away from their defaults, reset to them: their labels.
std::vector<std::string> drop_other_methods_fields(Method method, ExtractOptions& o) {
  std::vector<std::string> unused;
  const ExtractOptions defaults;
  auto drop = [&](auto& field, auto value, const char* label) {
    if (field != value) unused.push_back(label);
    field = value;
  };
  if (method != Method::Macet) {
    drop(o.quality, defaults.quality, "Macet quality");
    drop(o.macet_relax, defaults.macet_relax, "Macet relax");
  }
  if (method != Method::DualContouring) {
    drop(o.dc_solver, defaults.dc_solver, "DC solver");
    drop(o.dc_hermite, defaults.dc_hermite, "DC Hermite");
    drop(o.dc_vertices, defaults.dc_vertices, "DC vertices");
  }
  return unused;
}

// The fields as the pipeline's options. The enum indices are checked here (scripts carry
// indices, and the message lists the dialog's choices); the pipeline checks the rest (simplify,
// macet_relax, the backend) with the CLI's messages.
PipelineOptions pipeline_options(const IsosurfaceParams& p) {
  PipelineOptions po;
  ExtractOptions& o = po.extract;
  o.method = static_cast<Method>(checked_choice(p.method, kMethodNames, "'Method'"));
  o.quality = checked_choice(p.macet_quality, kMacetQualityNames, "'Macet quality'") == 1
                  ? MacetQuality::Max
                  : MacetQuality::Fast;
  o.macet_relax = p.macet_relax;
  const int solver = checked_choice(p.dc_solver, kDcSolverNames, "'DC solver'");
  o.dc_solver = solver == 1   ? DcSolver::Particle
                : solver == 2 ? DcSolver::Qef
                              : DcSolver::MassPoint;
  o.dc_hermite = checked_choice(p.dc_hermite, kDcHermiteNames, "'DC Hermite'") == 1
                     ? DcHermite::Eno
                     : DcHermite::Central;
  o.dc_vertices = checked_choice(p.dc_vertices, kDcVerticesNames, "'DC vertices'") == 1
                      ? DcVertices::Cell
                      : DcVertices::Patch;
  const int backend = checked_choice(p.backend, kBackendNames, "'Backend'");
  o.backend = backend == 1   ? Backend::Cpu
              : backend == 2 ? Backend::GeometryShader
              : backend == 3 ? Backend::HistoPyramid
                             : Backend::Auto;
  o.normals = p.normals;
  // The dialog's way to the automatic isovalue is nan, which the CLI's message does not know.
  if (!p.iso_auto && !std::isfinite(p.iso))
    throw InputError("'Isovalue' must be a finite number, or nan for the automatic isovalue");
  po.iso_auto = p.iso_auto;
  if (!p.iso_auto) po.iso = p.iso;
  po.simplify = p.simplify;
  po.memory = p.memory == "0" ? "" : p.memory;
  po.world_frame = true;  // the mesh in the volume's world coordinates, as `isotile extract`
  po.quality = true;      // the log's radius ratios
  po.range = true;        // the log's range of the samples
  return po;
}

// The library's progress (its stage, the brick, the fraction of the stage in that brick) onto
// MeshLab's bar and status line: reading to 25%, the histogram of --iso auto brick by brick to
// 30%, the extraction's stages (count, extract, Macet's search) from 30% to 60%, simplification
// from 60% to 90% (brick by brick: the bricks to 85%, their seams to 90%), the bricks' file after
// that. The extraction's stages are several, each from 0
// to 1 and their number not known ahead: a series over the span (core's stage_series_fraction).
// Bricks in flight at once finish out of order, so the bar takes the highest value told so far:
// it only moves forward.
class BarMapping {
 public:
  BarMapping(const Progress& report, std::string file_name, std::string method)
      : report_(report), file_name_(std::move(file_name)), method_(std::move(method)) {}

  bool operator()(const ProgressUpdate& u) {
    const bool extraction =
        u.stage == Stage::Count || u.stage == Stage::Extract || u.stage == Stage::MacetSearch;
    if (n_ == 0 || u.stage != stage_) n_ = extraction ? n_ + 1 : 0;
    stage_ = u.stage;
    const double done = std::clamp((static_cast<double>(u.brick) + u.fraction) /
                                       static_cast<double>(std::max<std::int64_t>(u.bricks, 1)),
                                   0.0, 1.0);
    double from = 0.02, width = 0.23;
    if (u.stage == Stage::Histogram) from = 0.25, width = 0.05;
    if (extraction) from = 0.3, width = 0.3;
    // Brick by brick, the seams' pass follows the bricks': its share is the last sixth.
    if (u.stage == Stage::Simplify) from = 0.6, width = u.bricks > 1 ? 0.25 : 0.3;
    if (u.stage == Stage::SimplifySeams) from = 0.85, width = 0.05;
    if (u.stage == Stage::Write) from = 0.9, width = 0;
    // The extraction's stages are a series (their number is not known ahead).
    bar_ = std::max(bar_, from + width * (extraction ? stage_series_fraction(n_, done) : done));
    report_(label(u), bar_);
    return true;
  }

 private:
  std::string label(const ProgressUpdate& u) const {
    const std::string bricks =
        u.bricks > 1 ? " brick " + std::to_string(u.brick + 1) + "/" + std::to_string(u.bricks)
                     : "";
    switch (u.stage) {
      case Stage::Read:
        return "reading " + file_name_;
      case Stage::Histogram:
        return "reading the samples' histogram for the isovalue";
      case Stage::Simplify:
        return u.bricks > 1 ? "simplify" + bricks : "simplifying";
      case Stage::SimplifySeams:
        return "simplifying the bricks' seams";
      case Stage::Write:
        return "writing";
      default:
        return u.bricks > 1 ? std::string(stage_name(u.stage)) + bricks
                            : "extracting (" + method_ + ")";
    }
  }

  const Progress& report_;
  std::string file_name_, method_;
  Stage stage_ = Stage::Read;
  int n_ = 0;  // the extraction's stages so far
  double bar_ = 0;
};

}  // namespace

std::string layer_name(const std::string& file, const std::string& series_description,
                       std::string_view method, double iso) {
  std::string base = series_description;
  if (base.empty()) base = file_stem(file);
  if (base.empty()) base = "volume";
  std::string name = base + " " + std::string(method) + " iso" + format_value(iso);
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

static IsosurfaceResult run_isosurface_checked(const IsosurfaceParams& p,
                                               const std::string& temp_dir,
                                               const Progress& progress);

IsosurfaceResult run_isosurface(const IsosurfaceParams& p, const std::string& temp_dir,
                                const Progress& progress) {
  try {
    return run_isosurface_checked(p, temp_dir, progress);
  } catch (const NoSurfaceError&) {
    throw;  // already in the dialog's terms
  } catch (const InputError& e) {
    throw InputError(in_dialog_terms(e.what()));
  } catch (const CapacityError& e) {
    throw CapacityError(in_dialog_terms(e.what()));
  }
}

std::string in_dialog_terms(std::string message) {
  // Longest first: "--method macet" before "--method", "--iso auto" before "--iso".
  static const std::pair<std::string_view, std::string_view> kTerms[] = {
      {"--method macet", "Method Macet"},
      {"--method dc", "Method Dual Contouring"},
      {"--method mc", "Method Marching Cubes"},
      {"--iso auto", "'Isovalue' nan"},
      {"--macet-relax", "'Macet relax'"},
      {"--quality", "'Macet quality'"},
      {"--dc-solver", "'DC solver'"},
      {"--dc-hermite", "'DC Hermite'"},
      {"--dc-vertices", "'DC vertices'"},
      {"--series", "'DICOM series'"},
      {"--dims X,Y,Z", "'Raw dims'"},
      {"--dims", "'Raw dims'"},
      {"--type T", "'Raw type'"},
      {"--type", "'Raw type'"},
      {"--endian", "'Raw byte order'"},
      {"--spacing", "'Spacing'"},
      {"--memory", "'Memory'"},
      {"--simplify", "'Simplify'"},
      {"--backend", "'Backend'"},
      {"--normals", "'Gradient normals'"},
      {"--iso", "'Isovalue'"},
      // The library's checks of the options struct name its fields.
      {"macet_relax must", "'Macet relax' must"},
      {"simplify must", "'Simplify' must"},
      {"big-endian", "'Raw byte order' big"},
  };
  return rename_options(std::move(message), kTerms);
}

static IsosurfaceResult run_isosurface_checked(const IsosurfaceParams& p,
                                               const std::string& temp_dir,
                                               const Progress& progress) {
  const auto t0 = Clock::now();
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
  PipelineOptions options = pipeline_options(p);
  std::vector<std::string> unused =
      drop_other_methods_fields(options.extract.method, options.extract);
  PipelineInput input;
  input.path = p.file;
  // Spelled as the CLI's options, which in_dialog_terms() turns into the dialog's labels.
  input.raw = parse_input_text(
      {.dims = p.dims, .type = p.type, .spacing = p.spacing, .origin = "", .endian = p.endian});
  input.raw.series = p.series;
  const std::string method(method_name(options.extract.method));
  BarMapping bar(progress, fs::path(p.file).filename().string(), method);
  isotile::Progress listening([&](const ProgressUpdate& u) { return bar(u); });
  if (progress) options.progress = &listening;  // else the library's loops skip the reports

  // Brick by brick the pipeline streams the mesh into a file, as the CLI's --memory does; it
  // goes in a private folder and MeshLab then holds the whole result.
  std::optional<PrivateFolder> tmp;
  fs::path mesh_file;
  if (!options.memory.empty()) {
    tmp.emplace(temp_dir.empty() ? temporary_folder() : fs::path(temp_dir));
    mesh_file = tmp->path / "bricks.ply";
    options.output = mesh_file.string();
  }
  IsosurfaceResult r;
  std::mutex said;  // a warning may come from a worker thread
  options.warn = [&](const std::string& line) {
    std::lock_guard lock(said);
    r.warnings.push_back(line);
  };
  PipelineResult run;
  try {
    run = run_pipeline(input, options);
  } catch (const NoSurfaceError& e) {
    // The library's finding (where the samples lie), with the ways out this dialog offers.
    throw NoSurfaceError("no surface at isovalue " + format_value(e.iso) + " in " + p.file + ": " +
                             e.finding +
                             (e.straddled ? "; choose another isovalue (nan: automatic) or method"
                                          : "; set the isovalue inside the range, or to nan for "
                                            "the automatic isovalue"),
                         e.iso, e.range, e.finding, e.straddled);
  }

  if (!mesh_file.empty()) {
    if (progress) progress("loading the bricks' mesh", 0.9);
    r.mesh = read_mesh(mesh_file);
  } else {
    r.mesh = std::move(run.mesh);
  }
  r.iso = run.iso;
  r.range = run.range;
  r.backend = std::string(backend_name(run.backend));
  r.bricks = run.bricks;
  r.triangles_extracted = run.triangles_extracted;
  r.quality = run.quality;
  r.unused_fields = std::move(unused);
  // A DICOM series without a description is named after its folder: the file chosen is any one
  // of its slices (00000060.dcm and 00000075.dcm gave two names to one series).
  std::error_code ec;
  const bool slice_of_series = !run.series_uid.empty() && !fs::is_directory(p.file, ec);
  r.layer_name = layer_name(slice_of_series && run.series_description.empty()
                                ? fs::absolute(p.file, ec).parent_path().string() + "/"
                                : p.file,
                            run.series_description, method, run.iso);
  r.description = p.file;
  if (!run.series_uid.empty())
    r.description += ", DICOM series " +
                     (run.series_description.empty() ? std::string("without a description")
                                                     : "'" + run.series_description + "'") +
                     " (" + run.series_uid + ")";
  r.description += ", " + std::string(kMethodNames[p.method]);
  if (options.extract.method == Method::Macet)
    r.description += std::string(" ") + kMacetQualityNames[p.macet_quality];
  r.description += ", isovalue " + format_value(run.iso);
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
  try {
    return simplify(mesh, o, stats);
  } catch (const InputError& e) {
    // The library's checks of the options, in the dialog's labels.
    static const std::pair<std::string_view, std::string_view> kTerms[] = {
        {"simplify: give a ratio, a face count or a maximum error",
         "give 'Faces kept (fraction)', 'Faces kept (count)' or 'Maximum error'"},
        {"simplify: the ratio", "'Faces kept (fraction)'"},
        {"simplify: the maximum error", "'Maximum error'"},
        {"simplify: the quality floor", "'Quality floor'"},
        {"simplify: the mesh", "the layer"},
    };
    throw InputError(rename_options(e.what(), kTerms));
  }
}

}  // namespace isotile::meshlab
