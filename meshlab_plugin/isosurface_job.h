// What the MeshLab filters ask of the libraries, without Qt or MeshLab: the isosurface filter's
// fields (as typed) turned into a run of the library's pipeline (tiler/pipeline.h, what
// `isotile extract` runs: the read, the extraction in core or brick by brick, the optional
// simplification); the simplify filter's fields turned into a simplification. The plugin only
// moves values and meshes between MeshLab and these functions, so that the work, the checks and
// the messages are the CLI's; what is MeshLab's own (the enum indices, the file field, the layer's
// name, the bar, the advice in terms of the dialog's fields) stays here.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/mesh/mesh_quality.h"
#include "core/simplify/simplify.h"

namespace isotile::meshlab {

// The isosurface filter's parameters, in declaration order (their names are the filter's).
struct IsosurfaceParams {
  std::string file;
  std::string dims, type, endian, spacing;  // raw files whose name does not say: text, or empty
  std::string series;                       // DICOM series UID; empty: the only one
  double iso = 0;
  // Choose the isovalue instead: Otsu's threshold of the samples (core/volume/otsu_isovalue.h),
  // as `isotile extract --iso auto`; `iso` is then ignored.
  bool iso_auto = false;
  int method = 0;         // 0 Marching Cubes, 1 Macet, 2 Dual Contouring
  int macet_quality = 0;  // 0 fast, 1 max
  double macet_relax = 0;
  int dc_solver = 0;         // 0 mass point, 1 particle, 2 QEF
  int dc_hermite = 0;        // 0 central, 1 ENO
  int dc_vertices = 0;       // 0 patch (manifold), 1 cell (the paper's)
  int backend = 0;           // 0 auto, 1 CPU, 2 geometry shader, 3 HistoPyramid
  std::string memory = "0";  // working-set budget of the extraction, e.g. "512MiB"; "0": in core
  double simplify = 1;       // fraction of faces kept; 1: off
  bool normals = false;      // gradient normals from the volume (else MeshLab's own)
};

// The file parameter's name patterns (one filter: MeshLab 2020.09 joins them with spaces), every
// extension the readers know, and "*" for DICOM files without one.
extern const char* const kVolumeFilePatterns[21];

// The choices of the enum parameters, in index order, as the dialog shows them.
extern const char* const kMethodNames[3];
extern const char* const kMacetQualityNames[2];
extern const char* const kDcSolverNames[3];
extern const char* const kDcHermiteNames[2];
extern const char* const kDcVerticesNames[2];
extern const char* const kBackendNames[4];

struct IsosurfaceResult {
  Mesh mesh;
  std::string layer_name;   // layer_name(): no dots, which MeshLab would cut
  std::string description;  // for the log: the file, DICOM series, method, isovalue in full
  double iso = 0;           // the isovalue used (chosen, with iso_auto)
  // The samples' lowest and highest value, where the run read them (PipelineResult::range:
  // always in core; brick by brick with iso_auto).
  std::optional<std::pair<double, double>> range;
  std::string backend;  // where it ran ("cpu", "gs", "hp")
  std::int64_t bricks = 1;
  std::uint64_t triangles_extracted = 0;
  QualityStats quality;
  double seconds = 0;
  // The fields of another method than the one chosen that were set away from their defaults
  // and so not used ("DC solver"): the dialog shows every method's fields at once and keeps
  // their last values, so they are left out with a line in the log rather than refused.
  std::vector<std::string> unused_fields;
  // The run's warnings (PipelineOptions::warn: a GPU backend's failure under auto, a memory
  // budget the surface overflows), in order, for the log: not on MeshLab's stderr, which a GUI
  // user never sees.
  std::vector<std::string> warnings;
};

// Progress: what is being done (the stage) and the fraction of the whole run done, in [0, 1].
using Progress = std::function<void(const std::string& stage, double fraction)>;

// A library message in the dialog's terms: the CLI's option names (--dc-solver, --method macet,
// --dims) become the fields' labels ('DC solver', Method Macet, 'Raw dims').
std::string in_dialog_terms(std::string message);

// The layer's name: the file's name without its extensions (a DICOM series: its description,
// else its folder's name), the method and the isovalue, with every '.' (MeshLab's layer list cuts
// a label at its last dot) and path separator replaced: "ch2 macet iso60_5".
std::string layer_name(const std::string& file, const std::string& series_description,
                       std::string_view method, double iso);

// `name`, or "name (2)", "name (3)", ... : the first that `taken` refuses, so that extracting
// the same file again gives a layer of its own name.
std::string unique_name(const std::string& name,
                        const std::function<bool(const std::string&)>& taken);

// Throws isotile::Error (InputError, IoError, CapacityError) with a message for the user: a bad
// or missing file, a malformed field, a feature not available yet, a GPU backend without GL, no
// surface at the isovalue. `temp_dir` receives a private folder of its own (mkdtemp: no other
// user can place a file or a link at the name written) holding the brick-by-brick extraction's
// file; both are removed before returning. `progress` hears the stage ("reading FILE",
// "extracting (macet)", brick by brick "extract brick 3/8", "simplifying", "loading the bricks'
// mesh") and a fraction of the whole run that only grows.
IsosurfaceResult run_isosurface(const IsosurfaceParams& params, const std::string& temp_dir,
                                const Progress& progress);

// The simplify filter: faces kept as a fraction (ratio), a count, or an error bound (mesh
// units); 0 leaves one out. Throws InputError like simplify().
struct SimplifyParams {
  double ratio = 0.1;
  std::uint64_t faces = 0;
  double max_error = 0;
  double min_quality = 0.3;
};
// `progress` hears the library's stage and the fraction of it done.
Mesh run_simplify(const Mesh& mesh, const SimplifyParams& params, SimplifyStats* stats,
                  const Progress& progress = {});

}  // namespace isotile::meshlab
