#include "core/extract/cell_mask.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/errors.h"

namespace isotile {

Mesh keep_masked_cells(const Mesh& mesh, const VolumeView& view, const VolumeView& mask) {
  if (mask.type != ScalarType::UInt8)
    throw InputError("the mask must hold uint8 (or bool) samples");
  if (mask.dims != view.dims) throw InputError("the mask must have the volume's dims");
  check_face_indices(mesh);
  const std::uint8_t* bits = mask.typed<std::uint8_t>();
  auto cell_inside = [&](auto corners_begin, std::size_t n) {
    double c[3] = {0, 0, 0};
    for (std::size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) c[a] += mesh.positions[corners_begin[i]][a];
    std::int64_t cell[3];
    for (int a = 0; a < 3; ++a) {
      const double g = (c[a] / static_cast<double>(n) - view.origin[a]) / view.spacing[a] -
                       static_cast<double>(view.box.lo[a]);
      cell[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor(g)), 0,
                                         std::max<std::int64_t>(view.dims[a] - 2, 0));
    }
    for (int k = 0; k < 8; ++k)
      if (!bits[mask.offset(cell[0] + (k & 1), cell[1] + ((k >> 1) & 1), cell[2] + (k >> 2))])
        return false;
    return true;
  };
  Mesh out;
  for (const Tri& t : mesh.triangles)
    if (cell_inside(t.begin(), 3)) out.triangles.push_back(t);
  for (const Quad& q : mesh.quads)
    if (cell_inside(q.begin(), 4)) out.quads.push_back(q);
  // Renumber the vertices still used, keeping their order.
  constexpr std::uint32_t kUnused = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> remap(mesh.positions.size(), kUnused);
  for (const Tri& t : out.triangles)
    for (std::uint32_t v : t) remap[v] = 0;
  for (const Quad& q : out.quads)
    for (std::uint32_t v : q) remap[v] = 0;
  std::uint32_t next = 0;
  for (std::size_t v = 0; v < remap.size(); ++v) {
    if (remap[v] == kUnused) continue;
    remap[v] = next++;
    out.positions.push_back(mesh.positions[v]);
    if (!mesh.normals.empty()) out.normals.push_back(mesh.normals[v]);
  }
  for (Tri& t : out.triangles)
    for (std::uint32_t& v : t) v = remap[v];
  for (Quad& q : out.quads)
    for (std::uint32_t& v : q) v = remap[v];
  return out;
}

}  // namespace isotile
