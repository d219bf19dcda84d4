// HistoPyramid pass 2: up to three levels of the count pyramid per dispatch. A node sums eight
// consecutive nodes (or elements) of the level below: (vertices, triangles) per node. Consecutive
// runs of eight keep the pyramid's traversal order equal to the element order, which is the CPU's
// output order.
// One invocation per node of level u_src_level + 1 sums its eight children (BASE: four words of
// codes, adjacent invocations reading adjacent 16 bytes); the workgroup keeps its 256 sums in
// shared memory and adds them up there into their 32 parents and 4 grandparents, writing each
// level it is asked for: one pass and one read of the level below instead of a pass per level,
// each re-reading the level just written.
// BASE: the level below is the elements (their codes, two per word); otherwise the pyramid level
// u_src_level. ONE_LEVEL_PER_PASS: the first level only, without shared memory and barriers
// (which cost a software rasteriser more than the passes they save; hp_pyramid.cpp).
layout(std430, binding = 1) readonly buffer Codes { uint codes[]; };
layout(std430, binding = 2) buffer Pyramid { uvec2 pyramid[]; };

uniform uint u_level_offset[16];  // level l >= 1 starts at pyramid[u_level_offset[l]]
uniform uint u_level_count[16];   // nodes of level l; level 0: the elements
uniform int u_src_level;          // the level read
uniform int u_steps;              // levels written above it: 1, 2 or 3

#ifndef ONE_LEVEL_PER_PASS
shared uvec2 s_node[256];
#endif

void main() {
  // No early return: every invocation reaches every barrier. Invocations past the last node
  // (the last group's tail, the 2D grid's padding) sum zeros and write nothing.
  uint p = invocation();
  uint t = gl_LocalInvocationIndex;
  uint src_count = u_level_count[u_src_level];
  uvec2 sum = uvec2(0u);
  for (uint c = 0u; c < 8u; ++c) {
    uint q = 8u * p + c;
    if (q >= src_count) break;
#ifdef BASE
    uint code = (codes[q >> 1] >> (16u * (q & 1u))) & 0xffffu;
    sum += uvec2(hp_vertex_count(code), hp_face_count(code));
#else
    sum += pyramid[u_level_offset[u_src_level] + q];
#endif
  }
  int l = u_src_level + 1;
  if (p < u_level_count[l]) pyramid[u_level_offset[l] + p] = sum;
#ifndef ONE_LEVEL_PER_PASS
  s_node[t] = sum;
  uint n = 256u;  // this group's nodes of level l, in s_node
  for (int j = 2; j <= u_steps; ++j) {
    n >>= 3;
    ++l;
    memoryBarrierShared();
    barrier();
    sum = uvec2(0u);
    if (t < n)
      for (uint c = 0u; c < 8u; ++c) sum += s_node[8u * t + c];
    // Every sum is read before any is stored over the nodes it was summed from.
    barrier();
    if (t < n) {
      s_node[t] = sum;
      uint q = n * (p >> 8) + t;
      if (q < u_level_count[l]) pyramid[u_level_offset[l] + q] = sum;
    }
  }
#endif
}
