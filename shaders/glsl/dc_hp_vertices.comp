// Dual Contouring on the HistoPyramid path, pass 3: the dual vertices, in key order (cell by
// cell, then patch), placed as core/extract/dual_contouring.cpp places it. Positions stay on the
// device for the quad pass's diagonal rule. main() is hp_output.glsl's.
layout(std430, binding = 6) readonly buffer PatchMaps { uint patch_maps[]; };
layout(std430, binding = 3) writeonly buffer Positions { float out_pos[]; };
#ifdef NORMALS
layout(std430, binding = 4) writeonly buffer Normals { float out_nrm[]; };
#endif

#define OUTPUT_KIND 0

// Element e's vertex of patch k, at slot i.
void emit_output(uint e, uint k, uint i) {
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
