// HistoPyramid pass 2b: the vertex offset of every node of level u_level (the number of vertices
// before its first element), top-down: its parent's offset plus its left siblings' counts. Lets
// a triangle corner find its vertex index from one offset and at most seven codes instead of
// summing left siblings on every level.
uniform int u_level;

void main() {
  uint p = invocation();
  if (p >= u_level_count[u_level]) return;
  uint sum = 0u;
  if (u_level < u_levels) {
    sum = vertex_offset[u_level_offset[u_level + 1] + (p >> 3)];
    for (uint q = p & ~7u; q < p; ++q) sum += pyramid[u_level_offset[u_level] + q].x;
  }
  vertex_offset[u_level_offset[u_level] + p] = sum;
}
