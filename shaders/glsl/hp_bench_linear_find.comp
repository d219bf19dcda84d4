// Benchmark only (tests/benchmarks/bench_hp_layouts.cpp): the production layout's descent
// (hp_common.glsl's find_element over eight consecutive nodes per level), one invocation per
// output, writing the linear index of the element the output belongs to.
layout(std430, binding = 3) writeonly buffer BenchOut { uint out_elem[]; };

uniform uint u_count;
uniform int u_which;  // 0: vertices, 1: triangles

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = i;
  out_elem[i] = find_element(k, u_which);
}
