#include "core/extract/dual_contouring_patches.h"

#include "core/extract/marching_cubes_tables.h"

namespace isotile::dc {

namespace {

// The four corners of face f in cyclic order, and the cube edge from corner i to corner i + 1.
struct Face {
  std::array<int, 4> corner;
  std::array<int, 4> edge;
};

Face face(int f) {
  const int axis = f / 2, side = f % 2;
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  Face out{};
  for (int i = 0; i < 4; ++i) out.corner[i] = (uv[i][0] << u) | (uv[i][1] << v) | (side << axis);
  for (int i = 0; i < 4; ++i)
    out.edge[i] = mc::detail::edge_between(out.corner[i], out.corner[(i + 1) % 4]);
  return out;
}

int find(std::array<int, 12>& root, int e) {
  while (root[e] != e) e = root[e] = root[root[e]];
  return e;
}

void join(std::array<int, 12>& root, int a, int b) {
  a = find(root, a);
  b = find(root, b);
  if (a != b) root[a < b ? b : a] = a < b ? a : b;
}

}  // namespace

CellPatches cell_patches(int cs, unsigned flips, unsigned open) {
  // Every crossing has one segment on each of the two faces its edge lies on; a patch is a cycle
  // of segments. On a face with two crossings the segment joins them; on an ambiguous face each
  // segment cuts off one inside corner (Marching Cubes' rule), or with the face flipped one
  // outside corner.
  std::array<int, 12> root{};
  for (int e = 0; e < 12; ++e) root[e] = e;
  for (int f = 0; f < 6; ++f) {
    if ((open >> f) & 1) continue;
    const Face fc = face(f);
    int crossed[4], n = 0;
    for (int i = 0; i < 4; ++i)
      if ((mc::kCaseTable.edge_mask[cs] >> fc.edge[i]) & 1) crossed[n++] = fc.edge[i];
    if (n == 2) join(root, crossed[0], crossed[1]);
    if (n != 4) continue;
    const bool cut_inside = !((flips >> f) & 1);
    for (int i = 0; i < 4; ++i) {
      const bool inside = (cs >> fc.corner[i]) & 1;
      // Corner i lies between edges i - 1 and i.
      if (inside == cut_inside) join(root, fc.edge[(i + 3) % 4], fc.edge[i]);
    }
  }
  // A piece whose edges all lie on the border gets no quad: it joins the first piece that does,
  // so it leaves no stray vertex; a cell where none does has no patch at all (live_edges()).
  if (open) {
    if (!has_vertex(cs, open)) {
      CellPatches none;
      none.patch.fill(-1);
      return none;
    }
    const unsigned on_border = border_edges(open);
    std::array<bool, 12> live{};
    int first_live = -1, first_dead = -1;
    for (int e = 0; e < 12; ++e)
      if (((mc::kCaseTable.edge_mask[cs] >> e) & 1) && !((on_border >> e) & 1))
        live[find(root, e)] = true;
    for (int e = 0; e < 12; ++e) {
      if (!((mc::kCaseTable.edge_mask[cs] >> e) & 1)) continue;
      const int r = find(root, e);
      if (live[r] && first_live < 0) first_live = r;
      if (!live[r] && first_dead < 0) first_dead = r;
    }
    const int keep = first_live >= 0 ? first_live : first_dead;
    for (int e = 0; e < 12; ++e)
      if (((mc::kCaseTable.edge_mask[cs] >> e) & 1) && !live[find(root, e)]) join(root, e, keep);
  }
  CellPatches out;
  std::array<int, 12> number{};
  number.fill(-1);
  for (int e = 0; e < 12; ++e) {
    out.patch[e] = -1;
    if (!((mc::kCaseTable.edge_mask[cs] >> e) & 1)) continue;
    const int r = find(root, e);
    if (number[r] < 0) number[r] = out.count++;
    out.patch[e] = static_cast<std::int8_t>(number[r]);
    if (number[r] < kMaxPatches) out.edges[number[r]] |= static_cast<std::uint16_t>(1u << e);
  }
  return out;
}

unsigned border_edges(unsigned open) {
  unsigned out = 0;
  for (int f = 0; f < 6; ++f)
    if ((open >> f) & 1)
      for (int e : face(f).edge) out |= 1u << e;
  return out;
}

unsigned live_edges(int cs, unsigned open) {
  return mc::kCaseTable.edge_mask[cs] & ~border_edges(open) & 0xfffu;
}

const std::array<std::uint8_t, 256> kConflictFaces = [] {
  std::array<std::uint8_t, 256> out{};
  for (int cs = 0; cs < 256; ++cs)
    for (int f = 0; f < 6; ++f) {
      const Face fc = face(f);
      bool ambiguous = true, one_patch = true;
      for (int i = 0; i < 4; ++i) {
        ambiguous = ambiguous && ((mc::kCaseTable.edge_mask[cs] >> fc.edge[i]) & 1);
        one_patch = one_patch && ambiguous &&
                    kPatchTable.patch[cs][fc.edge[i]] == kPatchTable.patch[cs][fc.edge[0]];
      }
      if (ambiguous && one_patch) out[cs] |= static_cast<std::uint8_t>(1u << f);
    }
  return out;
}();

}  // namespace isotile::dc
