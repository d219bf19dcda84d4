// Dual Contouring on the HistoPyramid path, pass 4: one invocation per quad, by its edge's lower
// sample and then axis (the CPU's order); its corners are the vertices serving the edge in its
// four cells, wound by the table of core/extract/dual_contouring_table.h. Without KEEP_QUADS each
// quad becomes two triangles by the CPU's diagonal rule.
layout(std430, binding = 6) readonly buffer PatchMaps { uint patch_maps[]; };
layout(std430, binding = 4) readonly buffer Positions { float pos[]; };
layout(std430, binding = 3) writeonly buffer Faces { uint out_face[]; };

uniform uint u_first;  // first quad of this chunk
uniform uint u_count;  // quads in this chunk

vec3 position(uint v) { return vec3(pos[3u * v], pos[3u * v + 1u], pos[3u * v + 2u]); }

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = u_first + i;
  uint e = find_element(k, 1);  // k: the rank of the quad's axis among the element's
  uint code = code_of(e);
  uint axes = (code >> 8) & 7u;
  int axis = 0;
  for (uint r = k; axis < 3; ++axis) {
    if (((axes >> axis) & 1u) == 0u) continue;
    if (r == 0u) break;
    --r;
  }
  ivec3 s = dc_element_cell(e);
  uint o = code & 1u;  // sample s inside
  uint row = (o << 3) | ((o * 7u) ^ axes);
  uint labels = dc_quads[3u * row + k];
  uint q[4];
  for (uint v = 0u; v < 4u; ++v) {
    uint n = (labels >> (4u * v)) & 15u;
    ivec3 c = s + dc_block_cell[n].xyz;
    uint edge = (dc_block_edge[n] >> (4 * axis)) & 15u;
    uint ce = dc_element_index(c);
#ifdef DC_PATCH
    q[v] = vertex_prefix(ce) + ((patch_maps[ce] >> (2u * edge)) & 3u);
#else
    q[v] = vertex_prefix(ce);
#endif
  }
#ifdef KEEP_QUADS
  for (uint v = 0u; v < 4u; ++v) out_face[4u * i + v] = q[v];
#else
  bool d13 = dc_split_13(position(q[0]), position(q[1]), position(q[2]), position(q[3]));
  out_face[6u * i + 0u] = q[0];
  out_face[6u * i + 1u] = q[1];
  out_face[6u * i + 2u] = d13 ? q[3] : q[2];
  out_face[6u * i + 3u] = d13 ? q[1] : q[0];
  out_face[6u * i + 4u] = q[2];
  out_face[6u * i + 5u] = q[3];
#endif
}
