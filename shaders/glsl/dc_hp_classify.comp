// Dual Contouring on the HistoPyramid path, pass 1: the code of every element (a vertex cell of
// the slab, dc_common.glsl) two per word, and the patch of each crossed edge of its cell (2 bits
// per edge) for the quad pass. One invocation per word.
layout(std430, binding = 1) writeonly buffer Codes { uint codes[]; };
layout(std430, binding = 6) writeonly buffer PatchMaps { uint patch_maps[]; };

uint dc_element_code(uint e) {
  ivec3 c = dc_element_cell(e);
  uint cs = cell_case(c);
  uint vertices = 0u, map = 0u;
  if (cs != 0u && cs != 255u) {
#ifdef DC_PATCH
    vertices = dc_cell_patches(c, cs, map);
#else
    vertices = dc_has_live_edge(c, cs) ? 1u : 0u;
#endif
  }
  patch_maps[e] = map;
  // The crossed edges of sample c (the cell's corner 0) that get a quad: c in the face box and
  // the four cells around the edge among the vertex cells (only the lower ones can be missing).
  uint axes = 0u;
  if (all(greaterThanEqual(c, u_box_lo)) && all(lessThan(c, u_box_hi))) {
    bvec3 mid = greaterThan(c, u_vlo);
    for (int a = 0; a < 3; ++a) {
      bool crossed = ((cs ^ (cs >> (1 << a))) & 1u) != 0u;
      if (crossed && mid[(a + 1) % 3] && mid[(a + 2) % 3]) axes |= 1u << a;
    }
  }
  return cs | (axes << 8) | (vertices << 11);
}

void main() {
  uint w = invocation();
  uint n = dc_element_count();
  if (2u * w >= n) return;
  // A loop of unknown length, so that dc_element_code is inlined once (it is large).
  uint word = 0u;
  for (uint e = 2u * w; e < min(2u * w + 2u, n); ++e) word |= dc_element_code(e) << (16u * (e & 1u));
  codes[w] = word;
}
