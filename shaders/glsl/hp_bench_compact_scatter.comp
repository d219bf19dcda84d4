// Benchmark only (tests/benchmarks/bench_hp_layouts.cpp), the "compact" output design: one
// invocation per element instead of one per output. An element with outputs finds where they go
// (its level-1 node's offsets from hp_bench_compact_sweep.comp plus its left siblings' counts, at
// most seven codes) and writes its own index into each of its vertex and triangle slots: the same
// arrays as the descents of the other layouts (hp_bench_linear_find.comp), with no descent.
layout(std430, binding = 6) readonly buffer NodeOffsets { uvec2 node_offset[]; };
layout(std430, binding = 3) writeonly buffer VertexOut { uint out_vertex[]; };
layout(std430, binding = 4) writeonly buffer TriangleOut { uint out_triangle[]; };

uvec2 counts_of(uint code) { return uvec2(leaf_count(code, 0), leaf_count(code, 1)); }

void main() {
  uint e = invocation();
  if (e >= u_level_count[0]) return;
  uvec2 n = counts_of(code_of(e));
  if (n.x == 0u && n.y == 0u) return;
  uvec2 o = node_offset[u_level_offset[1] + (e >> 3)];
  for (uint q = e & ~7u; q < e; ++q) o += counts_of(code_of(q));
  for (uint t = 0u; t < n.x; ++t) out_vertex[o.x + t] = e;
  for (uint t = 0u; t < n.y; ++t) out_triangle[o.y + t] = e;
}
