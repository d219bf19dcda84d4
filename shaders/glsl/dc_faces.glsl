// Dual Contouring's faces, shared by the HistoPyramid's quad pass and the geometry shader
// (prepended after hp_common.glsl): a quad's corners and the CPU's diagonal rule.
layout(std430, binding = 6) readonly buffer PatchMaps { uint patch_maps[]; };
layout(std430, binding = 4) readonly buffer Positions { float pos[]; };

vec3 dc_vertex_position(uint v) { return vec3(pos[3u * v], pos[3u * v + 1u], pos[3u * v + 2u]); }

// The slab-local indices of the quad of the edge of element e's sample along `axis`, the
// rank-th quad of the element: the vertices serving the edge in its four cells, wound by the
// table of core/extract/dual_contouring_table.h.
void dc_quad_corners(uint e, uint code, int axis, uint rank, out uint q[4]) {
  ivec3 s = dc_element_cell(e);
  uint o = code & 1u;  // sample s inside
  uint row = (o << 3) | ((o * 7u) ^ ((code >> 8) & 7u));
  uint labels = dc_quads[3u * row + rank];
  for (uint v = 0u; v < 4u; ++v) {
    uint n = (labels >> (4u * v)) & 15u;
    uint ce = dc_element_index(s + dc_block_cell[n].xyz);
#ifdef DC_PATCH
    uint edge = (dc_block_edge[n] >> (4 * axis)) & 15u;
    q[v] = vertex_prefix(ce) + ((patch_maps[ce] >> (2u * edge)) & 3u);
#else
    q[v] = vertex_prefix(ce);
#endif
  }
}

// Dual Contouring's diagonal rule (core/extract/dual_contouring.cpp's split, after
// triangle_quality's quad measure): 0-2 unless 1-3 leaves a strictly better worst triangle by
// radius ratio, computed in double from the float positions exactly as the CPU computes it.
double dc_length(vec3 p, vec3 q) {
  precise double dx = double(p.x) - double(q.x);
  precise double dy = double(p.y) - double(q.y);
  precise double dz = double(p.z) - double(q.z);
  precise double l2 = ((dx * dx) + dy * dy) + dz * dz;
  return sqrt_rn(l2);
}
double dc_ratio(double la, double lb, double lc) {
  if (la == 0.0LF || lb == 0.0LF || lc == 0.0LF) return 0.0LF;
  precise double q = ((((lb + lc) - la) * ((lc + la) - lb)) * ((la + lb) - lc)) / ((la * lb) * lc);
  if (!(q > 0.0LF)) return 0.0LF;
  return dc_min(q, 1.0LF);
}
// Whether quad q splits along 1-3: triangles (q0, q1, q3), (q1, q2, q3); else (q0, q1, q2),
// (q0, q2, q3).
bool dc_split_13(uint q[4]) {
  vec3 p0 = dc_vertex_position(q[0]), p1 = dc_vertex_position(q[1]);
  vec3 p2 = dc_vertex_position(q[2]), p3 = dc_vertex_position(q[3]);
  double s01 = dc_length(p0, p1), s12 = dc_length(p1, p2), s23 = dc_length(p2, p3);
  double s30 = dc_length(p3, p0), d02 = dc_length(p0, p2), d13 = dc_length(p1, p3);
  double a = dc_min(dc_ratio(s12, d02, s01), dc_ratio(s23, s30, d02));
  double b = dc_min(dc_ratio(d13, s30, s01), dc_ratio(s23, d13, s12));
  return b > a;
}

// The axis of the rank-th set bit of `axes`.
int dc_axis_of_rank(uint axes, uint rank) {
  int axis = 0;
  for (uint r = rank; axis < 3; ++axis) {
    if (((axes >> axis) & 1u) == 0u) continue;
    if (r == 0u) break;
    --r;
  }
  return axis;
}
