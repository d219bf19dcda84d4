#include "vtk_peer.h"

#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPolyData.h>
#include <vtkSMPTools.h>
#include <vtkSmartPointer.h>

#include <cstring>

namespace isotile::bench {

struct VtkFlyingEdges::Impl {
  vtkSmartPointer<vtkImageData> image;
};

namespace {
int vtk_type(ScalarType t) {
  switch (t) {
    case ScalarType::Int8:
      return VTK_SIGNED_CHAR;
    case ScalarType::UInt8:
      return VTK_UNSIGNED_CHAR;
    case ScalarType::Int16:
      return VTK_SHORT;
    case ScalarType::UInt16:
      return VTK_UNSIGNED_SHORT;
    case ScalarType::Int32:
      return VTK_INT;
    case ScalarType::UInt32:
      return VTK_UNSIGNED_INT;
    case ScalarType::Float32:
      return VTK_FLOAT;
    case ScalarType::Float64:
      break;
  }
  return VTK_DOUBLE;
}
}  // namespace

VtkFlyingEdges::VtkFlyingEdges(const VolumeView& v) : impl_(new Impl) {
  auto image = vtkSmartPointer<vtkImageData>::New();
  image->SetDimensions(static_cast<int>(v.dims[0]), static_cast<int>(v.dims[1]),
                       static_cast<int>(v.dims[2]));
  image->SetSpacing(v.spacing[0], v.spacing[1], v.spacing[2]);
  image->SetOrigin(v.origin[0], v.origin[1], v.origin[2]);
  image->AllocateScalars(vtk_type(v.type), 1);
  const std::size_t sample = scalar_size(v.type);
  auto* dst = static_cast<char*>(image->GetScalarPointer());
  for (std::int64_t k = 0; k < v.dims[2]; ++k)
    for (std::int64_t j = 0; j < v.dims[1]; ++j)
      std::memcpy(dst + ((k * v.dims[1] + j) * v.dims[0]) * sample,
                  static_cast<const char*>(v.data) + v.offset(0, j, k) * sample,
                  static_cast<std::size_t>(v.dims[0]) * sample);
  impl_->image = image;
}

VtkFlyingEdges::~VtkFlyingEdges() = default;

std::size_t VtkFlyingEdges::run(double iso) {
  vtkNew<vtkFlyingEdges3D> fe;
  fe->SetInputData(impl_->image);
  fe->SetValue(0, iso);
  fe->ComputeNormalsOff();
  fe->ComputeGradientsOff();
  fe->ComputeScalarsOff();
  fe->Update();
  return static_cast<std::size_t>(fe->GetOutput()->GetNumberOfPolys());
}

void VtkFlyingEdges::set_threads(int threads) {
  vtkSMPTools::SetBackend("TBB");
  vtkSMPTools::Initialize(threads);
}

const char* VtkFlyingEdges::backend() {
  return vtkSMPTools::GetBackend();
}

}  // namespace isotile::bench
