// HistoPyramid traversal, shared by the output passes (after mc_common.glsl).
layout(std430, binding = 1) readonly buffer Codes { uint codes[]; };
layout(std430, binding = 2) readonly buffer Pyramid { uvec2 pyramid[]; };
// Vertices before each node's first element, per node of levels 1..L (hp_downsweep.comp); with
// FACE_OFFSETS (the per-element output passes), the faces' follow, node for node.
layout(std430, binding = 5) buffer Offsets { uint vertex_offset[]; };

uniform int u_levels;             // L: level L is one node holding the totals
uniform uint u_level_offset[16];  // level l >= 1 starts at pyramid[u_level_offset[l]]
uniform uint u_level_count[16];   // nodes of level l; level 0: the elements

uint code_of(uint e) { return (codes[e >> 1] >> (16u * (e & 1u))) & 0xffffu; }
// which = 0: vertices, 1: faces (triangles; Dual Contouring's quads).
uint leaf_count(uint code, int which) {
  return which == 0 ? hp_vertex_count(code) : hp_face_count(code);
}

// Descends from the top node to the element holding output number k (of kind `which`); k becomes
// the rank of the output within that element. Children are visited in element order, so outputs
// come out in element order.
uint find_element(inout uint k, int which) {
  uint idx = 0u;
  for (int l = u_levels - 1; l >= 1; --l) {
    uint base = 8u * idx;
    for (uint c = 0u; c < 8u; ++c) {
      uint q = base + c;
      uint n = pyramid[u_level_offset[l] + q][which];
      if (k < n || c == 7u || q + 1u >= u_level_count[l]) {
        idx = q;
        break;
      }
      k -= n;
    }
  }
  uint base = 8u * idx;
  for (uint c = 0u; c < 8u; ++c) {
    uint e = base + c;
    uint n = leaf_count(code_of(e), which);
    if (k < n || c == 7u || e + 1u >= u_level_count[0]) return e;
    k -= n;
  }
  return base;
}

// Where node q's faces' offset is (FACE_OFFSETS only): after the vertices' offsets of all nodes
// (levels 1..L, the top level being one node).
uint face_offset_at(uint q) { return u_level_offset[u_levels] + 1u + q; }

// Number of outputs of kind `which` (0: vertices; 1: faces, FACE_OFFSETS only) of the elements
// before e: its level-1 node's offset plus its left siblings' counts.
uint output_prefix(uint e, int which) {
  uint node = u_level_offset[1] + (e >> 3);
  uint sum = vertex_offset[which == 0 ? node : face_offset_at(node)];
  for (uint q = e & ~7u; q < e; ++q) sum += leaf_count(code_of(q), which);
  return sum;
}
uint vertex_prefix(uint e) { return output_prefix(e, 0); }
