// VTK's vtkFlyingEdges3D behind a VTK-free interface: VTK 9.1's headers do not compile as C++20
// (vtkSMPTools.h declares constructors with template-ids), so vtk_peer.cpp is built as C++17.
#pragma once

#include <cstddef>
#include <memory>

#include "core/volume/volume.h"

namespace isotile::bench {

class VtkFlyingEdges {
 public:
  // Copies the samples into a vtkImageData once.
  explicit VtkFlyingEdges(const VolumeView& view);
  ~VtkFlyingEdges();
  // Runs vtkFlyingEdges3D (no normals, gradients or scalars); returns the triangle count.
  std::size_t run(double iso);
  static void set_threads(int threads);
  static const char* backend();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace isotile::bench
