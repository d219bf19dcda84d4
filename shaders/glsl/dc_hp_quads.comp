// Dual Contouring on the HistoPyramid path, pass 4: one invocation per quad, by its edge's lower
// sample and then axis (the CPU's order), from the face pyramid; without KEEP_QUADS two
// triangles by the CPU's diagonal rule (dc_faces.glsl).
layout(std430, binding = 3) writeonly buffer Faces { uint out_face[]; };

uniform uint u_first;  // first quad of this chunk
uniform uint u_count;  // quads in this chunk

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = u_first + i;
  uint e = find_element(k, 1);  // k: the rank of the quad among the element's
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
