// Benchmark only (tests/benchmarks/bench_hp_layouts.cpp), the "compact" output design: one level
// of the down-sweep for both kinds at once, top-down, (vertices, triangles) before each node's
// first element: its parent's offsets plus its left siblings' counts. hp_downsweep.comp does the
// vertices alone for the production path; the compact scatter needs the triangles' too.
layout(std430, binding = 6) buffer NodeOffsets { uvec2 node_offset[]; };

uniform int u_level;

void main() {
  uint p = invocation();
  if (p >= u_level_count[u_level]) return;
  uvec2 sum = uvec2(0u);
  if (u_level < u_levels) {
    sum = node_offset[u_level_offset[u_level + 1] + (p >> 3)];
    for (uint q = p & ~7u; q < p; ++q) sum += pyramid[u_level_offset[u_level] + q];
  }
  node_offset[u_level_offset[u_level] + p] = sum;
}
