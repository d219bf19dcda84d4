// OpenVDB volumes: the first float or double grid, densified over its active bounding box.
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/volume_io.h"

namespace isotile {

namespace {

void initialize_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

template <class GridT>
Volume densify(const std::string& path, const GridT& grid, ScalarType type) {
  using ValueT = typename GridT::ValueType;
  const openvdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
  if (bbox.empty()) throw InputError(path + ": grid '" + grid.getName() + "' has no active voxels");
  const openvdb::Coord dim = bbox.dim();
  const openvdb::Vec3d voxel = grid.voxelSize();
  const openvdb::Vec3d origin = grid.indexToWorld(bbox.min());
  Volume volume(type, {dim.x(), dim.y(), dim.z()}, {voxel.x(), voxel.y(), voxel.z()},
                {origin.x(), origin.y(), origin.z()});
  // CopyToDense fills voxels under no node with the background and those under a tile with the
  // tile's value, so inactive voxels get exactly what the grid reports for them.
  openvdb::tools::Dense<ValueT, openvdb::tools::LayoutXYZ> dense(bbox,
                                                                 volume.template data<ValueT>());
  openvdb::tools::copyToDense(grid, dense);
  return volume;
}

}  // namespace

Volume read_vdb(const std::string& path) {
  // OpenVDB says only "could not open file" for a missing one; keep the reason.
  if (std::FILE* probe = std::fopen(path.c_str(), "rb"))
    std::fclose(probe);
  else
    throw IoError("cannot open " + path + ": " + std::strerror(errno));

  initialize_openvdb();
  Volume volume;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    const openvdb::GridPtrVecPtr grids = file.readAllGridMetadata();
    std::optional<std::string> chosen;  // a grid may have an empty name
    std::string found;
    std::map<std::string, int> seen;
    for (const openvdb::GridBase::Ptr& g : *grids) {
      if (!found.empty()) found += ", ";
      found += "'" + g->getName() + "' (" + g->valueType() + ")";
      // A later grid that repeats a name is stored as "name[N]", as io::Archive writes it.
      const int repeat = seen[g->getName()]++;
      if (!chosen && (g->isType<openvdb::FloatGrid>() || g->isType<openvdb::DoubleGrid>()))
        chosen = repeat == 0 ? g->getName()
                             : openvdb::io::GridDescriptor::nameAsString(
                                   openvdb::io::GridDescriptor::addSuffix(g->getName(), repeat));
    }
    if (!chosen) {
      file.close();
      throw InputError(path + ": no float or double grid; found " +
                       (found.empty() ? std::string("no grids") : found));
    }
    const openvdb::GridBase::Ptr grid = file.readGrid(*chosen);
    file.close();
    if (const auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(grid))
      volume = densify(path, *fg, ScalarType::Float32);
    else if (const auto dg = openvdb::gridPtrCast<openvdb::DoubleGrid>(grid))
      volume = densify(path, *dg, ScalarType::Float64);
    else
      throw InputError(path + ": grid '" + *chosen + "' is not a float or double grid");
  } catch (const Error&) {
    throw;
  } catch (const openvdb::Exception& e) {
    throw InputError(path + ": not a readable OpenVDB file: " + e.what());
  } catch (const std::exception& e) {
    throw InputError(path + ": not a readable OpenVDB file: " + e.what());
  }
  check_finite(volume.view(), path);
  return volume;
}

}  // namespace isotile
