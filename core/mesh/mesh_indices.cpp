#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <string>

#include "core/errors.h"
#include "core/mesh/mesh.h"

namespace isotile {

void check_face_indices(const Mesh& mesh) {
  const std::size_t nv = mesh.positions.size();
  auto check = [&](const auto& faces, const char* what) {
    const std::size_t bad = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, faces.size(), 1 << 16), faces.size(),
        [&](const tbb::blocked_range<std::size_t>& r, std::size_t found) {
          for (std::size_t f = r.begin(); f < r.end() && f < found; ++f) {
            for (std::uint32_t v : faces[f]) {
              if (v >= nv) return f;
            }
          }
          return found;
        },
        [](std::size_t a, std::size_t b) { return std::min(a, b); });
    if (bad == faces.size()) return;
    std::uint32_t v = 0;
    for (std::uint32_t c : faces[bad]) v = c >= nv ? c : v;
    throw InputError(std::string(what) + " " + std::to_string(bad) + " references vertex " +
                     std::to_string(v) + " but the mesh has " + std::to_string(nv) + " vertices");
  };
  check(mesh.triangles, "triangle");
  check(mesh.quads, "quad");
}

}  // namespace isotile
