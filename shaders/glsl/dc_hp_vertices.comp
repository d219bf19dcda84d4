// Dual Contouring on the HistoPyramid path, pass 3: one invocation per dual vertex, in key order
// (cell by cell, then patch), placed as core/extract/dual_contouring.cpp places it. Positions
// stay on the device for the quad pass's diagonal rule.
layout(std430, binding = 6) readonly buffer PatchMaps { uint patch_maps[]; };
layout(std430, binding = 3) writeonly buffer Positions { float out_pos[]; };
#ifdef NORMALS
layout(std430, binding = 4) writeonly buffer Normals { float out_nrm[]; };
#endif

uniform uint u_count;  // vertices of the slab

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = i;
  uint e = find_element(k, 0);  // k: the patch
  uint cs = code_of(e) & 0xffu;
  ivec3 c = dc_element_cell(e);
  uint edges = case_edge_mask(cs);
#ifdef DC_PATCH
  uint map = patch_maps[e], mine = 0u;
  for (int m = 0; m < 12; ++m)
    if (((edges >> m) & 1u) != 0u && ((map >> (2 * m)) & 3u) == k) mine |= 1u << m;
  edges = mine;
#endif
  dvec3 x = dc_place(c, edges);
  vec3 p = dc_position(c, x);
  for (int a = 0; a < 3; ++a) out_pos[3u * i + uint(a)] = p[a];
#ifdef NORMALS
  vec3 n = dc_vertex_normal(c, x);
  for (int a = 0; a < 3; ++a) out_nrm[3u * i + uint(a)] = n[a];
#endif
}
