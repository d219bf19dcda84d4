// HistoPyramid pass 2: one level of the count pyramid. A node sums eight consecutive nodes (or
// elements) of the level below: (vertices, triangles) per node. Consecutive runs of eight keep the
// pyramid's traversal order equal to the element order, which is the CPU's output order.
// BASE: the level below is the elements (their codes); otherwise the pyramid level at
// u_src_offset.
layout(std430, binding = 1) readonly buffer Codes { uint codes[]; };
layout(std430, binding = 2) buffer Pyramid { uvec2 pyramid[]; };

uniform uint u_count;      // nodes of the level written
uniform uint u_src_count;  // nodes (elements) of the level below
uniform uint u_src_offset;
uniform uint u_dst_offset;

void main() {
  uint p = invocation();
  if (p >= u_count) return;
  uvec2 sum = uvec2(0u);
  for (uint c = 0u; c < 8u; ++c) {
    uint q = 8u * p + c;
    if (q >= u_src_count) break;
#ifdef BASE
    uint code = (codes[q >> 1] >> (16u * (q & 1u))) & 0xffffu;
    sum += uvec2(hp_vertex_count(code), hp_face_count(code));
#else
    sum += pyramid[u_src_offset + q];
#endif
  }
  pyramid[u_dst_offset + p] = sum;
}
