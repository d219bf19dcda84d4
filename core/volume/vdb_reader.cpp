// OpenVDB volumes: the first float or double grid, densified over its active bounding box.
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Dense.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/volume/volume_io.h"

// OpenVDB reads a grid cut short at its end without a word (the last leaf's missing bytes are
// whatever its buffer held). The grid descriptors say where each grid ends, but io::File keeps them
// private, readable by its friend ::TestFile (OpenVDB's own unit test, not part of the library):
// this class of that name reads them, and nothing else.
class TestFile {
 public:
  static std::int64_t grids_end(const openvdb::io::File& file) {
    std::int64_t end = 0;
    for (const auto& entry : file.gridDescriptors())
      end = std::max<std::int64_t>(end, entry.second.getEndPos());
    return end;
  }
};

namespace isotile {

namespace {

void initialize_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

template <class GridT>
class TreeVolume final : public VdbVolume {
 public:
  using ValueT = typename GridT::ValueType;
  TreeVolume(const std::string& path, typename GridT::Ptr grid, ScalarType t)
      : grid_(std::move(grid)) {
    bbox_ = grid_->evalActiveVoxelBoundingBox();
    if (bbox_.empty())
      throw InputError(path + ": grid '" + grid_->getName() + "' has no active voxels");
    const openvdb::Coord dim = bbox_.dim();
    const openvdb::Vec3d voxel = grid_->voxelSize();
    const openvdb::Vec3d o = grid_->indexToWorld(bbox_.min());
    type = t;
    dims = {dim.x(), dim.y(), dim.z()};
    spacing = {voxel.x(), voxel.y(), voxel.z()};
    origin = {o.x(), o.y(), o.z()};
  }

  void read_box(const Box3& box, void* out) const override {
    const openvdb::Coord lo =
        bbox_.min() + openvdb::Coord(static_cast<int>(box.lo[0]), static_cast<int>(box.lo[1]),
                                     static_cast<int>(box.lo[2]));
    const openvdb::Coord hi = bbox_.min() + openvdb::Coord(static_cast<int>(box.hi[0] - 1),
                                                           static_cast<int>(box.hi[1] - 1),
                                                           static_cast<int>(box.hi[2] - 1));
    // CopyToDense fills voxels under no node with the background and those under a tile with the
    // tile's value, so inactive voxels get exactly what the grid reports for them.
    openvdb::tools::Dense<ValueT, openvdb::tools::LayoutXYZ> dense(openvdb::CoordBBox(lo, hi),
                                                                   static_cast<ValueT*>(out));
    openvdb::tools::copyToDense(*grid_, dense);
  }

 private:
  typename GridT::Ptr grid_;
  openvdb::CoordBBox bbox_;
};

}  // namespace

std::unique_ptr<VdbVolume> open_vdb(const std::string& path) {
  // OpenVDB says only "could not open file" for a missing one; keep the reason.
  if (std::FILE* probe = std::fopen(path.c_str(), "rb"))
    std::fclose(probe);
  else
    throw IoError("cannot open " + path + ": " + std::strerror(errno));
  initialize_openvdb();
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    std::error_code ec;
    const auto size = static_cast<std::int64_t>(std::filesystem::file_size(path, ec));
    if (const std::int64_t end = TestFile::grids_end(file); !ec && end > size)
      throw InputError(path + ": OpenVDB grids end at byte " + std::to_string(end) +
                       " but the file holds " + std::to_string(size) + " (truncated file)");
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
    if (auto fg = openvdb::gridPtrCast<openvdb::FloatGrid>(grid))
      return std::make_unique<TreeVolume<openvdb::FloatGrid>>(path, fg, ScalarType::Float32);
    if (auto dg = openvdb::gridPtrCast<openvdb::DoubleGrid>(grid))
      return std::make_unique<TreeVolume<openvdb::DoubleGrid>>(path, dg, ScalarType::Float64);
    throw InputError(path + ": grid '" + *chosen + "' is not a float or double grid");
  } catch (const Error&) {
    throw;
  } catch (const openvdb::Exception& e) {
    throw InputError(path + ": not a readable OpenVDB file: " + e.what());
  } catch (const std::exception& e) {
    throw InputError(path + ": not a readable OpenVDB file: " + e.what());
  }
}

}  // namespace isotile
