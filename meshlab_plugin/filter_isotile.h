// isotile's MeshLab 2020.09 filter plugin: "Isosurface from Volume File (isotile)" under
// Filters > Create New Mesh Layer, and "Simplification: isotile Shape-Preserving Collapse" under
// Filters > Remeshing, Simplification and Reconstruction.
//
// The plugin moves parameters and meshes between MeshLab and the libraries
// (meshlab_plugin/isosurface_job.h does the rest without Qt). It runs the work on a thread of its
// own: MeshLab's GLX context is current on its thread, and an EGL context (the GL backends')
// cannot be made current on a thread that has one.
#pragma once

#include <common/interfaces.h>

#include <QObject>

class FilterIsotile : public QObject, public MeshFilterInterface {
  Q_OBJECT
  MESHLAB_PLUGIN_IID_EXPORTER(MESH_FILTER_INTERFACE_IID)
  Q_INTERFACES(MeshFilterInterface)

 public:
  enum { FP_ISOSURFACE, FP_SIMPLIFY };

  FilterIsotile();

  QString pluginName() const override;
  QString filterName(FilterIDType filter) const override;
  QString filterInfo(FilterIDType filter) const override;
  FilterClass getClass(QAction* a) override;
  FILTER_ARITY filterArity(QAction* a) const override;
  int getPreConditions(QAction* a) const override;
  int postCondition(QAction* a) const override;
  // The MeshDocument overload: meshlabserver calls it with no current mesh for a filter that
  // creates one, where the MeshModel overload's default would dereference null.
  void initParameterSet(QAction* a, MeshDocument& md, RichParameterList& par) override;
  bool applyFilter(QAction* a, MeshDocument& md, const RichParameterList& par,
                   vcg::CallBackPos* cb) override;

 private:
  bool isosurface(MeshDocument& md, const RichParameterList& par, vcg::CallBackPos* cb);
  bool simplify(MeshDocument& md, const RichParameterList& par, vcg::CallBackPos* cb);
  bool fail(const QString& message);
};
