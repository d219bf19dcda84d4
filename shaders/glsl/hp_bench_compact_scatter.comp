// Benchmark only (tests/benchmarks/bench_hp_layouts.cpp), the "compact" output design: one
// invocation per element instead of one per output. An element with outputs finds where they go
// (output_prefix(): its level-1 node's offsets from the production down-sweep with FACE_OFFSETS
// plus its left siblings' counts) and writes its own index into each of its vertex and triangle
// slots: the same arrays as the descents of the other layouts (hp_bench_linear_find.comp), with
// no descent.
layout(std430, binding = 3) writeonly buffer VertexOut { uint out_vertex[]; };
layout(std430, binding = 4) writeonly buffer TriangleOut { uint out_triangle[]; };

void main() {
  uint e = invocation();
  if (e >= u_level_count[0]) return;
  uint code = code_of(e);
  uint nv = leaf_count(code, 0), nt = leaf_count(code, 1);
  if (nv == 0u && nt == 0u) return;
  uint ov = output_prefix(e, 0), ot = output_prefix(e, 1);
  for (uint t = 0u; t < nv; ++t) out_vertex[ov + t] = e;
  for (uint t = 0u; t < nt; ++t) out_triangle[ot + t] = e;
}
