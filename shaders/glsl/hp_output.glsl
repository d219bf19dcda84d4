// The HistoPyramid output passes' main, appended after each pass (hp_vertices.comp,
// hp_triangles.comp, dc_hp_vertices.comp, dc_hp_quads.comp), which defines OUTPUT_KIND (0:
// vertices, 1: faces) and emit_output(e, k, i): write the element e's output of rank k among its
// own at slot i of this chunk's buffers. Outputs come in element order either way, so the mesh
// does not depend on the design (hp_pyramid.h's HpOutput).
uniform uint u_first;  // first output of this chunk
uniform uint u_count;  // outputs in this chunk

void main() {
#ifdef SCATTER_OUTPUT
  // One invocation per element: its outputs start at its level-1 node's offset plus its left
  // siblings' counts (no descent); it writes those that fall in this chunk.
  uint e = invocation();
  if (e >= u_level_count[0]) return;
  uint n = leaf_count(code_of(e), OUTPUT_KIND);
  if (n == 0u) return;
  uint first = output_prefix(e, OUTPUT_KIND);
  uint lo = max(first, u_first), hi = min(first + n, u_first + u_count);
  for (uint k = lo; k < hi; ++k) emit_output(e, k - first, k - u_first);
#else
  // One invocation per output, descending the pyramid to its element (hp_common.glsl).
  uint i = invocation();
  if (i >= u_count) return;
  uint k = u_first + i;
  uint e = find_element(k, OUTPUT_KIND);
  emit_output(e, k, i);
#endif
}
