// Dual Contouring on the geometry-shader path: the quads of an element's sample in axis order
// (the CPU's order), each as two triangles by the CPU's diagonal rule or, with KEEP_QUADS, as four
// points; captured by transform feedback as slab-local vertex indices, with the element's index
// so that a capture that ran out of room can be resumed at an element boundary.
layout(points) in;
#ifdef KEEP_QUADS
layout(points, max_vertices = 12) out;
#else
layout(triangle_strip, max_vertices = 18) out;
#endif

flat in uint v_elem[];

flat out uint tf_vertex;
flat out uint tf_elem;

void emit(uint v, uint e) {
  tf_vertex = v;
  tf_elem = e;
  EmitVertex();
#ifdef KEEP_QUADS
  EndPrimitive();
#endif
}

void main() {
  uint e = v_elem[0];
  uint code = code_of(e);
  uint axes = (code >> 8) & 7u;
  // A loop of unknown length: unrolled three times over, the shader took seconds to compile on
  // llvmpipe.
  uint n = uint(bitCount(axes));
  for (uint rank = 0u; rank < n; ++rank) {
    uint q[4];
    dc_quad_corners(e, code, dc_axis_of_rank(axes, rank), rank, q);
#ifdef KEEP_QUADS
    for (uint v = 0u; v < 4u; ++v) emit(q[v], e);
#else
    bool d13 = dc_split_13(q);
    emit(q[0], e);
    emit(q[1], e);
    emit(d13 ? q[3] : q[2], e);
    EndPrimitive();
    emit(d13 ? q[1] : q[0], e);
    emit(q[2], e);
    emit(q[3], e);
    EndPrimitive();
#endif
  }
}
