// Dual Contouring on the HistoPyramid path, pass 4: the quads, by their edge's lower sample and
// then axis (the CPU's order), from the face pyramid; without KEEP_QUADS two triangles by the
// CPU's diagonal rule (dc_faces.glsl). main() is hp_output.glsl's.
layout(std430, binding = 3) writeonly buffer Faces { uint out_face[]; };

#define OUTPUT_KIND 1

// Element e's quad of rank k among its own, at slot i.
void emit_output(uint e, uint k, uint i) {
  uint code = code_of(e);
  uint q[4];
  dc_quad_corners(e, code, dc_axis_of_rank((code >> 8) & 7u, k), k, q);
#ifdef KEEP_QUADS
  for (uint v = 0u; v < 4u; ++v) out_face[4u * i + v] = q[v];
#else
  bool d13 = dc_split_13(q);
  out_face[6u * i + 0u] = q[0];
  out_face[6u * i + 1u] = q[1];
  out_face[6u * i + 2u] = d13 ? q[3] : q[2];
  out_face[6u * i + 3u] = d13 ? q[1] : q[0];
  out_face[6u * i + 4u] = q[2];
  out_face[6u * i + 5u] = q[3];
#endif
}
