#include "meshlab_plugin/filter_isotile.h"

#include <vcg/complex/algorithms/update/bounding.h>
#include <vcg/complex/algorithms/update/color.h>
#include <vcg/complex/algorithms/update/normal.h>

#include <QApplication>
#include <QDir>
#include <QMainWindow>
#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <future>
#include <limits>
#include <mutex>
#include <string>
#include <thread>

#include "core/errors.h"
#include "core/mesh/mesh_quality.h"
#include "meshlab_plugin/isosurface_job.h"
#ifdef ISOTILE_HAVE_GL
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#endif

namespace {

namespace ml = isotile::meshlab;

QStringList choices(const char* const* names, int n) {
  QStringList out;
  for (int i = 0; i < n; ++i) out << names[i];
  return out;
}

// True inside MeshLab's GUI (its main window exists), false in meshlabserver. The two differ
// in what they show: the GUI logs a failed filter's message itself ("Filter failed: ...") and
// shows progress in its status bar; meshlabserver prints neither the message (only "Problem
// with filter") nor a line break after a progress text.
bool in_gui() {
  for (QWidget* w : QApplication::topLevelWidgets())
    if (qobject_cast<QMainWindow*>(w)) return true;
  return false;
}

// The one place where isotile's progress, a stage and the fraction of the run done (0..1),
// becomes MeshLab's callback. Call it on MeshLab's thread only (the callback may touch widgets).
// The GUI shows the text in its status bar and the percentage in its bar; meshlabserver prints
// the text whenever the percentage changes, so it gets the percentage and a line of its own.
class MeshlabProgress {
 public:
  explicit MeshlabProgress(vcg::CallBackPos* cb) : cb_(cb), gui_(in_gui()) {}
  void operator()(const std::string& stage, double fraction) {
    if (!cb_) return;
    const int percent = static_cast<int>(std::lround(std::clamp(fraction, 0.0, 1.0) * 100));
    if (percent == percent_ && stage == stage_) return;
    percent_ = percent;
    stage_ = stage;
    const std::string text =
        gui_ ? "isotile: " + stage : "isotile: " + stage + " (" + std::to_string(percent) + "%)\n";
    cb_(percent, text.c_str());
  }

 private:
  vcg::CallBackPos* cb_;
  bool gui_;
  int percent_ = -1;
  std::string stage_;
};

// Runs `work` on a thread of its own (see filter_isotile.h) while this thread hands its progress
// to MeshLab's callback, which may touch widgets and so must stay on MeshLab's thread. Rethrows
// what `work` threw.
template <class T, class Work>
T on_own_thread(MeshlabProgress& to_meshlab, Work&& work) {
  std::mutex m;
  double fraction = 0;
  std::string stage;
  bool reported = false;
  const ml::Progress progress = [&](const std::string& s, double f) {
    std::lock_guard<std::mutex> lock(m);
    fraction = f;
    stage = s;
    reported = true;
  };
  std::packaged_task<T()> task([&] {
#ifdef ISOTILE_HAVE_GL
    // The job's GL context ends with the job, on the thread that used it, in a known order
    // (docs/gl.md): nothing GL is left for MeshLab's exit. A later GL job makes a new one.
    struct EndGl {
      ~EndGl() { isotile::gl::shutdown(); }
    } end_gl;
#endif
    return work(progress);
  });
  std::future<T> done = task.get_future();
  std::thread worker(std::move(task));
  auto hand_over = [&] {
    std::lock_guard<std::mutex> lock(m);
    if (reported) to_meshlab(stage, fraction);
  };
  while (done.wait_for(std::chrono::milliseconds(100)) != std::future_status::ready) hand_over();
  worker.join();
  hand_over();        // the last stage, even of a run shorter than one wait
  return done.get();  // rethrows
}

// Per-face quality: the radius ratio; per-vertex: the worst of its faces.
void set_quality(MeshModel& m) {
  m.updateDataMask(MeshModel::MM_FACEQUALITY | MeshModel::MM_VERTQUALITY);
  for (CVertexO& v : m.cm.vert) v.Q() = 1;
  for (CFaceO& f : m.cm.face) {
    if (f.IsD()) continue;
    auto p = [&](int i) {
      const auto& c = f.V(i)->P();
      return isotile::Vec3f{static_cast<float>(c[0]), static_cast<float>(c[1]),
                            static_cast<float>(c[2])};
    };
    f.Q() = static_cast<float>(isotile::radius_ratio(p(0), p(1), p(2)));
    for (int i = 0; i < 3; ++i) f.V(i)->Q() = std::min(f.V(i)->Q(), f.Q());
  }
}

// Fills an empty layer with `mesh`.
void fill(MeshModel& m, const isotile::Mesh& mesh) {
  auto vi = vcg::tri::Allocator<CMeshO>::AddVertices(m.cm, mesh.positions.size());
  const bool normals = !mesh.normals.empty();
  for (std::size_t i = 0; i < mesh.positions.size(); ++i, ++vi) {
    const auto& p = mesh.positions[i];
    vi->P() = Point3m(p[0], p[1], p[2]);
    if (normals) vi->N() = Point3m(mesh.normals[i][0], mesh.normals[i][1], mesh.normals[i][2]);
  }
  auto fi = vcg::tri::Allocator<CMeshO>::AddFaces(m.cm, mesh.triangles.size());
  for (const isotile::Tri& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) fi->V(k) = &m.cm.vert[t[k]];
    ++fi;
  }
  if (normals) {
    // The extractor's gradient normals stay; faces get theirs from the geometry.
    vcg::tri::UpdateBounding<CMeshO>::Box(m.cm);
    vcg::tri::UpdateNormal<CMeshO>::PerFaceNormalized(m.cm);
  } else {
    m.UpdateBoxAndNormals();
  }
  set_quality(m);
}

// The isosurface filter's colouring: each face's quality (radius ratio) on MeshLab's ramp, red 0
// to blue 1.
void colour_by_quality(MeshModel& m) {
  m.updateDataMask(MeshModel::MM_FACECOLOR);
  vcg::tri::UpdateColor<CMeshO>::PerFaceQualityRamp(m.cm, 0, 1);
}

// True when every face's colour is the ramp colour of its quality, as colour_by_quality() paints
// it: colours that can be painted again from the simplified mesh's quality.
bool coloured_by_quality(const MeshModel& m) {
  if (!m.hasDataMask(MeshModel::MM_FACECOLOR) || !m.hasDataMask(MeshModel::MM_FACEQUALITY))
    return false;
  for (const CFaceO& f : m.cm.face) {
    if (f.IsD()) continue;
    vcg::Color4b ramp;
    ramp.SetColorRamp(0, 1, f.cQ());
    if (f.cC() != ramp) return false;
  }
  return true;
}

}  // namespace

FilterIsotile::FilterIsotile() {
  typeList << FP_ISOSURFACE << FP_SIMPLIFY;
  for (FilterIDType t : typeList) actionList << new QAction(filterName(t), this);
#ifdef ISOTILE_HAVE_GL
  isotile::gl::register_gl_backends();
#endif
}

QString FilterIsotile::pluginName() const {
  return "FilterIsotile";
}

QString FilterIsotile::filterName(FilterIDType filter) const {
  switch (filter) {
    case FP_ISOSURFACE:
      return "Isosurface from Volume File (isotile)";
    case FP_SIMPLIFY:
      return "Simplification: Shape-Preserving Edge Collapse (isotile)";
  }
  return {};
}

QString FilterIsotile::filterInfo(FilterIDType filter) const {
  switch (filter) {
    case FP_ISOSURFACE:
      // Short: the dialog shows it above 18 fields, on screens down to 1280x800.
      return "A volume file's isosurface as a new layer (isotile: Marching Cubes, Macet, Dual "
             "Contouring). Isovalue nan: automatic; the log shows the samples' range.";
    case FP_SIMPLIFY:
      return "Simplifies the current mesh by edge collapses that keep its topology, its border "
             "(boundary vertices do not move) and well-shaped triangles (no new triangle below "
             "the radius-ratio floor; flips and tangential relaxation afterwards), with plane "
             "quadrics for the error. Non-manifold vertices and edges are kept as they are. "
             "Per-face quality becomes the radius ratio. The whole layer is simplified (a face "
             "selection is not a limit, and is not kept).";
  }
  return {};
}

FilterIsotile::FilterClass FilterIsotile::getClass(QAction* a) {
  return ID(a) == FP_ISOSURFACE ? MeshFilterInterface::MeshCreation
                                : MeshFilterInterface::Remeshing;
}

MeshFilterInterface::FILTER_ARITY FilterIsotile::filterArity(QAction* a) const {
  return ID(a) == FP_ISOSURFACE ? NONE : SINGLE_MESH;
}

int FilterIsotile::getPreConditions(QAction* a) const {
  return ID(a) == FP_ISOSURFACE ? MeshModel::MM_NONE : MeshModel::MM_FACENUMBER;
}

int FilterIsotile::postCondition(QAction* a) const {
  if (ID(a) == FP_ISOSURFACE) return MeshModel::MM_NONE;  // a new layer
  // New faces and vertices: their quality, and colours painted again or dropped.
  return MeshModel::MM_GEOMETRY_AND_TOPOLOGY_CHANGE | MeshModel::MM_FACEQUALITY |
         MeshModel::MM_VERTQUALITY | MeshModel::MM_FACECOLOR | MeshModel::MM_VERTCOLOR |
         MeshModel::MM_VERTTEXCOORD | MeshModel::MM_WEDGTEXCOORD;
}

void FilterIsotile::initParameterSet(QAction* a, MeshDocument& /*md*/, RichParameterList& par) {
  if (ID(a) == FP_SIMPLIFY) {
    par.addParam(
        RichFloat("ratio", 0.1f, "Faces kept (fraction)",
                  "The fraction of the faces to keep, in (0, 1]; used when 'Faces kept (count)' is "
                  "0. 0 with a 'Maximum error': that bound alone"));
    par.addParam(RichInt("faces", 0, "Faces kept (count)",
                         "The number of faces to keep; 0: use the fraction"));
    par.addParam(RichFloat("max_error", 0.0f, "Maximum error",
                           "Stop before any vertex strays further than this (in the mesh's "
                           "units) from the surface it replaces; 0: no bound"));
    par.addParam(RichFloat("min_quality", 0.3f, "Quality floor",
                           "Radius ratio (0..1) below which collapses may not create triangles, "
                           "and up to which the cleanup works"));
    return;
  }
  // Short labels, the details in the help: 18 fields fit a 1280x800 screen only so. The names
  // stay as they are: meshlabserver 2020.09 aborts on a script lacking a declared parameter.
  const ml::IsosurfaceParams d;
  QStringList patterns;
  for (const char* pattern : ml::kVolumeFilePatterns) patterns << pattern;
  par.addParam(RichOpenFile("file", "", patterns, "Volume file",
                            "raw, raw.gz, NRRD/NHDR, OpenVDB, NIfTI, MetaImage, TIFF, MRC/CCP4, or "
                            "any file of a DICOM series. Choose it with the '...' button: MeshLab "
                            "2020.09 ignores a path typed into the box"));
  par.addParam(RichString("dims", "", "Raw dims",
                          "Raw files whose name does not say: samples along x,y,z, e.g. "
                          "256,256,128; empty otherwise"));
  par.addParam(RichString("type", "", "Raw type",
                          "Raw files whose name does not say: int8, uint8, int16, uint16, int32, "
                          "uint32, float32 or float64; empty otherwise"));
  par.addParam(RichString("endian", "", "Raw byte order",
                          "Raw files: little (default) or big; empty: little"));
  par.addParam(RichString("spacing", "", "Spacing",
                          "Sample spacing x,y,z, e.g. 0.5,0.5,1 (overrides the file's); empty: "
                          "the file's, or 1"));
  par.addParam(RichString("series", "", "DICOM series",
                          "DICOM series UID where the file's folder holds several; empty: the "
                          "series of the file chosen"));
  // NaN, shown as "nan", is the automatic isovalue: no parameter of its own, which would break
  // every existing script (see above).
  par.addParam(RichFloat("iso", std::numeric_limits<float>::quiet_NaN(), "Isovalue (nan: auto)",
                         "Samples at or above it are inside. nan (the default): chosen from the "
                         "samples (Otsu's threshold, as isotile extract --iso auto). The log "
                         "shows the samples' range and the isovalue used: this dialog cannot "
                         "show them when the file is chosen"));
  par.addParam(RichEnum("method", d.method, choices(ml::kMethodNames, 3), "Method",
                        "Marching Cubes; Macet (better-shaped triangles); Dual Contouring"));
  par.addParam(RichEnum("macet_quality", d.macet_quality, choices(ml::kMacetQualityNames, 2),
                        "Macet quality",
                        "fast: closed-form push of the edge end points; max: adds a local "
                        "search for the worst triangles (much slower)"));
  par.addParam(RichFloat("macet_relax", static_cast<float>(d.macet_relax), "Macet relax",
                         "Macet only: moves samples pinned in one-sample-thin features, in [0, "
                         "0.5) edge lengths; 0: off"));
  par.addParam(RichEnum("dc_solver", d.dc_solver, choices(ml::kDcSolverNames, 3), "DC solver",
                        "Dual Contouring's vertex placement: mass point (best triangles), "
                        "particle (the paper's minimizer), QEF (sharp features)"));
  par.addParam(RichEnum("dc_hermite", d.dc_hermite, choices(ml::kDcHermiteNames, 2), "DC Hermite",
                        "Dual Contouring's Hermite data: central differences, or ENO "
                        "(kink-aware: sharper edges and corners)"));
  par.addParam(RichEnum("dc_vertices", d.dc_vertices, choices(ml::kDcVerticesNames, 2),
                        "DC vertices",
                        "Dual Contouring: patch: one vertex per surface patch of a cell, a "
                        "manifold mesh; cell: one vertex per cell (the paper's table; "
                        "non-manifold edges where a cell holds several sheets)"));
  par.addParam(RichEnum("backend", d.backend, choices(ml::kBackendNames, 4), "Backend",
                        "Auto (the CPU: no GPU path is measured faster yet; docs/gl.md), CPU, "
                        "or OpenGL: geometry shader or HistoPyramid"));
  par.addParam(RichString("memory", QString::fromStdString(d.memory), "Memory",
                          "Extract brick by brick within this working set, e.g. 512MiB; 0: in "
                          "core. MeshLab still holds the whole result"));
  par.addParam(RichFloat("simplify", static_cast<float>(d.simplify), "Simplify",
                         "Fraction of the faces kept, in (0, 1]; 1: off"));
  par.addParam(RichBool("normals", d.normals, "Gradient normals",
                        "Vertex normals from the volume's gradient; otherwise from the faces"));
  par.addParam(RichBool("colour_by_quality", false, "Colour by quality",
                        "Colour the faces by their radius ratio on MeshLab's red (0) to blue "
                        "(1) ramp; simplifying the layer paints them again"));
}

bool FilterIsotile::fail(const QString& message) {
  errorMessage = message;
  // The GUI logs the message itself ("Filter failed: ..."); meshlabserver prints only "Problem
  // with filter", so there the log carries it.
  if (!in_gui()) Log(GLLogStream::SYSTEM, "isotile: %s", qUtf8Printable(message));
  return false;
}

bool FilterIsotile::applyFilter(QAction* a, MeshDocument& md, const RichParameterList& par,
                                vcg::CallBackPos* cb) {
  try {
    return ID(a) == FP_ISOSURFACE ? isosurface(md, par, cb) : simplify(md, par, cb);
  } catch (const isotile::Error& e) {
    return fail(e.what());
  } catch (const std::bad_alloc&) {
    return fail("out of memory");
  } catch (const std::exception& e) {
    return fail(QString("unexpected error: ") + e.what());
  }
}

namespace {

// The number typed in the dialog or script, from the float MeshLab keeps: the shortest decimal
// that reads back as that float, read as a double, as the CLI reads the same text (0.3 is stored
// as 0.30000001192...; taken as it is, Macet's relaxation moved other vertices than the CLI's
// --macet-relax 0.3, and iso 60.3 gave other positions than --iso 60.3).
double typed(float value) {
  char text[32];
  const auto end = std::to_chars(text, text + sizeof text, value).ptr;
  return std::strtod(std::string(text, end).c_str(), nullptr);
}

}  // namespace

bool FilterIsotile::isosurface(MeshDocument& md, const RichParameterList& par,
                               vcg::CallBackPos* cb) {
  ml::IsosurfaceParams p;
  p.file = par.getOpenFileName("file").toStdString();
  p.dims = par.getString("dims").trimmed().toStdString();
  p.type = par.getString("type").trimmed().toStdString();
  p.endian = par.getString("endian").trimmed().toStdString();
  p.spacing = par.getString("spacing").trimmed().toStdString();
  p.series = par.getString("series").trimmed().toStdString();
  p.iso = typed(par.getFloat("iso"));
  p.iso_auto = std::isnan(p.iso);
  p.method = par.getEnum("method");
  p.macet_quality = par.getEnum("macet_quality");
  p.macet_relax = typed(par.getFloat("macet_relax"));
  p.dc_solver = par.getEnum("dc_solver");
  p.dc_hermite = par.getEnum("dc_hermite");
  p.dc_vertices = par.getEnum("dc_vertices");
  p.backend = par.getEnum("backend");
  p.memory = par.getString("memory").trimmed().toStdString();
  p.simplify = typed(par.getFloat("simplify"));
  p.normals = par.getBool("normals");
  const bool colour = par.getBool("colour_by_quality");
  const std::string temp = QDir::tempPath().toStdString();

  MeshlabProgress to_meshlab(cb);
  const ml::IsosurfaceResult r = on_own_thread<ml::IsosurfaceResult>(
      to_meshlab,
      [&](const ml::Progress& progress) { return ml::run_isosurface(p, temp, progress); });

  // The layer appears only now that its mesh is complete; a failure while filling it removes it.
  // A name of its own: MeshLab's own disambiguation ("name(1)") cuts at dots and drops the rest.
  const std::string label = ml::unique_name(r.layer_name, [&](const std::string& name) {
    for (const MeshModel* other : md.meshList)
      if (other->label() == QString::fromStdString(name)) return true;
    return false;
  });
  MeshModel* m = md.addNewMesh("", QString::fromStdString(label), true);
  try {
    fill(*m, r.mesh);
  } catch (...) {
    md.delMesh(m);
    throw;
  }
  if (colour) colour_by_quality(*m);
  Log("isotile: layer '%s': %s", label.c_str(), r.description.c_str());
  if (r.range)
    Log("isotile: samples from %.10g to %.10g; isovalue %.10g%s", r.range->first, r.range->second,
        r.iso, p.iso_auto ? " (automatic: Otsu's threshold of the samples)" : "");
  else
    Log("isotile: isovalue %.10g", r.iso);
  Log("isotile: %llu triangles, %zu vertices; radius ratio min %.4g, mean %.4g; %lld brick(s) "
      "on %s; %.2f s",
      static_cast<unsigned long long>(r.mesh.triangles.size()), r.mesh.positions.size(),
      r.quality.min, r.quality.mean, static_cast<long long>(r.bricks), r.backend.c_str(),
      r.seconds);
  if (p.simplify < 1)
    Log("isotile: simplified from %llu triangles",
        static_cast<unsigned long long>(r.triangles_extracted));
  if (!r.unused_fields.empty()) {
    std::string fields;
    for (const std::string& f : r.unused_fields) fields += (fields.empty() ? "" : ", ") + f;
    Log("isotile: not used by %s: %s", ml::kMethodNames[p.method], fields.c_str());
  }
  for (const std::string& line : r.warnings)
    Log(GLLogStream::WARNING, "isotile: warning: %s", line.c_str());
  return true;
}

bool FilterIsotile::simplify(MeshDocument& md, const RichParameterList& par, vcg::CallBackPos* cb) {
  MeshModel* m = md.mm();
  if (m == nullptr || m->cm.fn == 0) return fail("the current layer has no faces to simplify");
  ml::SimplifyParams p;
  p.ratio = typed(par.getFloat("ratio"));
  p.faces = static_cast<std::uint64_t>(std::max(0, par.getInt("faces")));
  p.max_error = typed(par.getFloat("max_error"));
  p.min_quality = typed(par.getFloat("min_quality"));
  if (par.getInt("faces") < 0)
    return fail("'Faces kept (count)' must be 0 (use the fraction) or more");

  // The layer as plain arrays (deleted elements left out).
  isotile::Mesh in;
  std::vector<std::uint32_t> index(m->cm.vert.size(), 0);
  for (std::size_t i = 0; i < m->cm.vert.size(); ++i) {
    const CVertexO& v = m->cm.vert[i];
    if (v.IsD()) continue;
    index[i] = static_cast<std::uint32_t>(in.positions.size());
    in.positions.push_back(
        {static_cast<float>(v.P()[0]), static_cast<float>(v.P()[1]), static_cast<float>(v.P()[2])});
  }
  std::uint64_t selected = 0;  // not a limit here: the whole layer is simplified (the log says)
  for (const CFaceO& f : m->cm.face) {
    if (f.IsD()) continue;
    selected += f.IsS();
    isotile::Tri t;
    for (int k = 0; k < 3; ++k)
      t[k] = index[static_cast<std::size_t>(vcg::tri::Index(m->cm, f.cV(k)))];
    in.triangles.push_back(t);
  }
  // What the new faces and vertices can carry over: the quality ramp the isosurface filter
  // painted is painted again from the new quality; other colours and texture coordinates
  // belonged to faces and vertices that no longer exist.
  const bool recolour = coloured_by_quality(*m);
  QStringList dropped;
  if (m->hasDataMask(MeshModel::MM_FACECOLOR) && !recolour) dropped << "face colours";
  if (m->hasDataMask(MeshModel::MM_VERTCOLOR)) dropped << "vertex colours";
  if (m->hasDataMask(MeshModel::MM_VERTTEXCOORD) || m->hasDataMask(MeshModel::MM_WEDGTEXCOORD))
    dropped << "texture coordinates";

  MeshlabProgress to_meshlab(cb);
  const std::string start = "simplifying " + std::to_string(in.triangles.size()) + " triangles";
  to_meshlab(start, 0);
  const auto t0 = std::chrono::steady_clock::now();
  isotile::SimplifyStats stats;
  const isotile::Mesh out =
      on_own_thread<isotile::Mesh>(to_meshlab, [&](const ml::Progress& progress) {
        // Short of 100% until the end: meshlabserver prints a text only when the percentage
        // changes, and the end has a text of its own.
        return ml::run_simplify(in, p, &stats,
                                [&](const std::string&, double f) { progress(start, 0.95 * f); });
      });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  to_meshlab("simplified to " + std::to_string(out.triangles.size()) + " triangles", 1);
  m->cm.Clear();
  if (!dropped.isEmpty())
    m->clearDataMask(MeshModel::MM_FACECOLOR | MeshModel::MM_VERTCOLOR |
                     MeshModel::MM_VERTTEXCOORD | MeshModel::MM_WEDGTEXCOORD);
  fill(*m, out);
  if (recolour) colour_by_quality(*m);
  const isotile::QualityStats q = isotile::triangle_quality(out);
  Log("isotile: simplified %llu to %llu triangles; radius ratio min %.4g, mean %.4g; %llu "
      "non-manifold vertices split and welded back; %.2f s",
      static_cast<unsigned long long>(stats.faces_before),
      static_cast<unsigned long long>(out.triangles.size()), q.min, q.mean,
      static_cast<unsigned long long>(stats.split_vertices), seconds);
  if (recolour) Log("isotile: faces coloured again by their new quality");
  if (!dropped.isEmpty())
    Log("isotile: dropped the layer's %s: they belonged to the faces and vertices the "
        "simplification replaced",
        qUtf8Printable(dropped.join(", ")));
  if (selected > 0)
    Log("isotile: the whole layer was simplified; its selection of %llu faces was not kept (it "
        "named faces that no longer exist)",
        static_cast<unsigned long long>(selected));
  // As `isotile simplify` warns, at MeshLab's warning level; the layer is the result all the same.
  if (const std::string missed = isotile::target_missed(stats); !missed.empty()) {
    // Vertices mostly on borders: faces that share corners without sharing vertices (a mesh
    // saved unwelded, every face with its own three), which no collapse may join.
    const bool unwelded = 2 * stats.boundary_vertices > in.positions.size();
    Log(GLLogStream::WARNING, "isotile: warning: %s%s", missed.c_str(),
        unwelded ? "; most vertices lie on borders: an unwelded mesh? Merge its vertices first "
                   "(Filters > Cleaning and Repairing > Remove Duplicate Vertices)"
                 : "");
  }
  return true;
}

MESHLAB_PLUGIN_NAME_EXPORTER(FilterIsotile)
