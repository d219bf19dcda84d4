// HistoPyramid pass 3: the vertices, in key order (MACET: Macet's vertex on the edge,
// macet_common.glsl); main() is hp_output.glsl's.
layout(std430, binding = 3) writeonly buffer Positions { float out_pos[]; };
#ifdef NORMALS
layout(std430, binding = 4) writeonly buffer Normals { float out_nrm[]; };
#endif

#define OUTPUT_KIND 0

// The k-th vertex of element e, at slot i.
void emit_output(uint e, uint k, uint i) {
  uint bits = code_of(e) >> 8;
  int axis = 0;
  for (; axis < 2; ++axis) {  // the k-th crossed edge of the element
    if (((bits >> axis) & 1u) == 0u) continue;
    if (k == 0u) break;
    --k;
  }
  vec3 p, n;
#ifdef MACET
  macet_edge_vertex(element_sample(e), axis, p, n);
#else
  edge_vertex(element_sample(e), axis, p, n);
#endif
  for (int c = 0; c < 3; ++c) out_pos[3u * i + uint(c)] = p[c];
#ifdef NORMALS
  for (int c = 0; c < 3; ++c) out_nrm[3u * i + uint(c)] = n[c];
#endif
}
