#include "meshlab_plugin/filter_isotile.h"

#include <vcg/complex/algorithms/update/bounding.h>
#include <vcg/complex/algorithms/update/color.h>
#include <vcg/complex/algorithms/update/normal.h>

#include <QDir>
#include <chrono>
#include <cmath>
#include <exception>
#include <future>
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

// Runs `work` on a thread of its own (see filter_isotile.h) while this thread hands its progress
// to MeshLab's callback, which may touch widgets and so must stay on MeshLab's thread. Rethrows
// what `work` threw.
template <class T, class Work>
T on_own_thread(vcg::CallBackPos* cb, Work&& work) {
  std::mutex m;
  int percent = 0;
  std::string what;
  const ml::Progress progress = [&](int p, const std::string& w) {
    std::lock_guard<std::mutex> lock(m);
    percent = p;
    what = w;
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
  while (done.wait_for(std::chrono::milliseconds(100)) != std::future_status::ready) {
    if (!cb) continue;
    std::lock_guard<std::mutex> lock(m);
    cb(percent, what.c_str());
  }
  worker.join();
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
      return "Extracts the isosurface of a volume file (raw, raw.gz, NRRD/NHDR, OpenVDB, NIfTI, "
             "MetaImage, TIFF, MRC/CCP4, a DICOM series through any of its files) as a new "
             "layer, in the volume's world coordinates, with isotile: Marching Cubes, Macet "
             "(Marching Cubes with edge "
             "transformations: well-shaped triangles) or table-driven Dual Contouring, on the "
             "CPU or in OpenGL shaders, in core or brick by brick within a memory budget, "
             "optionally simplified. Per-face quality is the triangle's radius ratio (1: "
             "equilateral), per-vertex quality the worst of its faces.<br>"
             "A raw file named NAME_XxYxZ_TYPE.raw[.gz] needs no dims or type.<br>See: "
             "<i>Schmitz, Dietrich, Comba</i>, <b>\"Efficient and High Quality Contouring of "
             "Isosurfaces on Uniform Grids\"</b>, SIBGRAPI 2009.";
    case FP_SIMPLIFY:
      return "Simplifies the current mesh by edge collapses that keep its topology, its border "
             "(boundary vertices do not move) and well-shaped triangles (no new triangle below "
             "the radius-ratio floor; flips and tangential relaxation afterwards), with plane "
             "quadrics for the error. Non-manifold vertices and edges are kept as they are. "
             "Per-face quality becomes the radius ratio.";
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
  return MeshModel::MM_GEOMETRY_AND_TOPOLOGY_CHANGE | MeshModel::MM_FACEQUALITY |
         MeshModel::MM_VERTQUALITY;
}

void FilterIsotile::initParameterSet(QAction* a, MeshDocument& /*md*/, RichParameterList& par) {
  if (ID(a) == FP_SIMPLIFY) {
    par.addParam(RichFloat("ratio", 0.1f, "Faces kept (fraction)",
                           "The fraction of the faces to keep, in (0, 1]; used when 'faces' is 0"));
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
  const ml::IsosurfaceParams d;
  par.addParam(RichOpenFile("file", "",
                            QStringList() << "*.raw *.gz *.nrrd *.nhdr *.vdb *.nii *.mha *.mhd "
                                             "*.tif *.tiff *.mrc *.map *.ccp4 *.dcm"
                                          << "*",
                            "Volume file",
                            "raw, raw.gz, NRRD/NHDR, OpenVDB, NIfTI, MetaImage, TIFF (multi-page), "
                            "MRC/CCP4, or any file of a DICOM series"));
  par.addParam(RichString("dims", "", "Dimensions",
                          "Raw files whose name does not say: samples along x,y,z, e.g. "
                          "256,256,128; empty otherwise"));
  par.addParam(RichString("type", "", "Sample type",
                          "Raw files whose name does not say: int8, uint8, int16, uint16, int32, "
                          "uint32, float32 or float64; empty otherwise"));
  par.addParam(
      RichString("endian", "", "Byte order", "Raw files: little (default) or big; empty: little"));
  par.addParam(RichString("spacing", "", "Spacing",
                          "Sample spacing x,y,z, e.g. 0.5,0.5,1 (overrides the file's); empty: "
                          "the file's, or 1"));
  par.addParam(RichString("series", "", "DICOM series",
                          "DICOM series UID where the file's directory holds several; empty: "
                          "the series of the file chosen"));
  // No parameter of its own for the automatic isovalue: meshlabserver 2020.09 aborts on a script
  // that lacks a declared parameter, so a new one would break every existing script.
  par.addParam(RichFloat("iso", static_cast<float>(d.iso), "Isovalue",
                         "Samples at or above it are inside; nan: chosen from the samples (Otsu's "
                         "threshold, as isotile extract --iso auto; the log gives the value)"));
  par.addParam(RichEnum("method", d.method, choices(ml::kMethodNames, 3), "Method",
                        "Marching Cubes; Macet (better-shaped triangles); Dual Contouring"));
  par.addParam(RichEnum("macet_quality", d.macet_quality, choices(ml::kMacetQualityNames, 2),
                        "Macet quality",
                        "fast: closed-form push of the edge end points; max: adds a local "
                        "search for the worst triangles (much slower)"));
  par.addParam(RichFloat("macet_relax", static_cast<float>(d.macet_relax), "Macet relaxation",
                         "Macet only: moves samples pinned in one-sample-thin features, in [0, "
                         "0.5) edge lengths; 0: off"));
  par.addParam(RichEnum("dc_solver", d.dc_solver, choices(ml::kDcSolverNames, 3),
                        "Dual Contouring vertex placement",
                        "mass point (best triangles), particle (the paper's minimizer), QEF "
                        "(sharp features)"));
  par.addParam(RichEnum("dc_hermite", d.dc_hermite, choices(ml::kDcHermiteNames, 2),
                        "Dual Contouring Hermite data",
                        "central differences, or ENO (kink-aware: sharper edges and corners)"));
  par.addParam(RichEnum("dc_vertices", d.dc_vertices, choices(ml::kDcVerticesNames, 2),
                        "Dual Contouring vertices",
                        "patch: one vertex per surface patch of a cell, a manifold mesh; cell: "
                        "one vertex per cell (the paper's table; non-manifold edges where a cell "
                        "holds several sheets)"));
  par.addParam(RichEnum("backend", d.backend, choices(ml::kBackendNames, 4), "Backend",
                        "Auto (the CPU: no GPU path is measured faster yet; docs/gl.md), CPU, "
                        "or OpenGL: geometry shader or HistoPyramid"));
  par.addParam(RichString("memory", QString::fromStdString(d.memory), "Memory budget",
                          "Extract brick by brick within this working set, e.g. 512MiB; 0: in "
                          "core. MeshLab still holds the whole result"));
  par.addParam(RichFloat("simplify", static_cast<float>(d.simplify), "Simplify",
                         "Fraction of the faces kept, in (0, 1]; 1: off"));
  par.addParam(RichBool("normals", d.normals, "Gradient normals",
                        "Vertex normals from the volume's gradient; otherwise from the faces"));
  par.addParam(RichBool("colour_by_quality", false, "Colour by quality",
                        "Colour the faces by their radius ratio on MeshLab's red (0) to blue "
                        "(1) ramp"));
}

bool FilterIsotile::fail(const QString& message) {
  errorMessage = message;
  // meshlabserver prints only "Problem with filter"; the log reaches its output.
  Log(GLLogStream::SYSTEM, "isotile: %s", qUtf8Printable(message));
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

bool FilterIsotile::isosurface(MeshDocument& md, const RichParameterList& par,
                               vcg::CallBackPos* cb) {
  ml::IsosurfaceParams p;
  p.file = par.getOpenFileName("file").toStdString();
  p.dims = par.getString("dims").trimmed().toStdString();
  p.type = par.getString("type").trimmed().toStdString();
  p.endian = par.getString("endian").trimmed().toStdString();
  p.spacing = par.getString("spacing").trimmed().toStdString();
  p.series = par.getString("series").trimmed().toStdString();
  p.iso = par.getFloat("iso");
  p.iso_auto = std::isnan(p.iso);
  p.method = par.getEnum("method");
  p.macet_quality = par.getEnum("macet_quality");
  p.macet_relax = par.getFloat("macet_relax");
  p.dc_solver = par.getEnum("dc_solver");
  p.dc_hermite = par.getEnum("dc_hermite");
  p.dc_vertices = par.getEnum("dc_vertices");
  p.backend = par.getEnum("backend");
  p.memory = par.getString("memory").trimmed().toStdString();
  p.simplify = par.getFloat("simplify");
  p.normals = par.getBool("normals");
  const bool colour = par.getBool("colour_by_quality");
  const std::string temp = QDir::tempPath().toStdString();

  const ml::IsosurfaceResult r = on_own_thread<ml::IsosurfaceResult>(
      cb, [&](const ml::Progress& progress) { return ml::run_isosurface(p, temp, progress); });
  if (r.mesh.triangles.empty())
    return fail(QString("no surface at isovalue %1 in %2 (see its value range with `isotile "
                        "info`)")
                    .arg(r.iso)
                    .arg(QString::fromStdString(p.file)));

  // The layer appears only now that its mesh is complete; a failure while filling it removes it.
  MeshModel* m = md.addNewMesh("", QString::fromStdString(r.layer_name), true);
  try {
    fill(*m, r.mesh);
  } catch (...) {
    md.delMesh(m);
    throw;
  }
  if (colour) {
    m->updateDataMask(MeshModel::MM_FACECOLOR);
    vcg::tri::UpdateColor<CMeshO>::PerFaceQualityRamp(m->cm, 0, 1);
  }
  Log("isotile: %llu triangles, %zu vertices; radius ratio min %.4f, mean %.4f; %lld brick(s) "
      "on %s; %.2f s",
      static_cast<unsigned long long>(r.mesh.triangles.size()), r.mesh.positions.size(),
      r.quality.min, r.quality.mean, static_cast<long long>(r.bricks), r.backend.c_str(),
      r.seconds);
  if (p.iso_auto) Log("isotile: isovalue %g (Otsu's threshold of the samples)", r.iso);
  if (p.simplify < 1)
    Log("isotile: simplified from %llu triangles",
        static_cast<unsigned long long>(r.triangles_extracted));
  return true;
}

bool FilterIsotile::simplify(MeshDocument& md, const RichParameterList& par, vcg::CallBackPos* cb) {
  MeshModel* m = md.mm();
  if (m == nullptr || m->cm.fn == 0) return fail("the current layer has no faces to simplify");
  ml::SimplifyParams p;
  p.ratio = par.getFloat("ratio");
  p.faces = static_cast<std::uint64_t>(std::max(0, par.getInt("faces")));
  p.max_error = par.getFloat("max_error");
  p.min_quality = par.getFloat("min_quality");
  if (par.getInt("faces") < 0) return fail("faces must be 0 (use the fraction) or more");

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
  for (const CFaceO& f : m->cm.face) {
    if (f.IsD()) continue;
    isotile::Tri t;
    for (int k = 0; k < 3; ++k)
      t[k] = index[static_cast<std::size_t>(vcg::tri::Index(m->cm, f.cV(k)))];
    in.triangles.push_back(t);
  }
  const auto t0 = std::chrono::steady_clock::now();
  isotile::SimplifyStats stats;
  const isotile::Mesh out = on_own_thread<isotile::Mesh>(
      cb, [&](const ml::Progress&) { return ml::run_simplify(in, p, &stats); });
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  m->cm.Clear();
  fill(*m, out);
  const isotile::QualityStats q = isotile::triangle_quality(out);
  Log("isotile: simplified %llu to %llu triangles; radius ratio min %.4f, mean %.4f; %llu "
      "non-manifold vertices split and welded back; %.2f s",
      static_cast<unsigned long long>(stats.faces_before),
      static_cast<unsigned long long>(out.triangles.size()), q.min, q.mean,
      static_cast<unsigned long long>(stats.split_vertices), seconds);
  return true;
}

MESHLAB_PLUGIN_NAME_EXPORTER(FilterIsotile)
