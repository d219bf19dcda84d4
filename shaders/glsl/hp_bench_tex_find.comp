// Benchmark only: descent of the 3D-texture pyramid (hp_bench_tex_classify.comp), one invocation
// per output, writing the linear (z, y, x) index of the output's element. Level l's texture is on
// texture unit l (unit 0: the codes); the loop index is dynamically uniform, as sampler-array
// indexing requires.
layout(binding = 0) uniform usampler3D u_tlev[16];
layout(std430, binding = 3) writeonly buffer BenchOut { uint out_elem[]; };

uniform uvec3 u_tdims[16];
uniform int u_tlevels;  // L: level L is one texel
uniform uint u_count;
uniform int u_which;

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = i;
  uvec3 p = uvec3(0u);
  for (int l = u_tlevels - 1; l >= 0; --l) {
    uvec3 base = 2u * p;
    for (uint c = 0u; c < 8u; ++c) {
      uvec3 q = base + uvec3(c & 1u, (c >> 1) & 1u, (c >> 2) & 1u);
      uint n = 0u;
      if (all(lessThan(q, u_tdims[l]))) {
        uvec4 t = texelFetch(u_tlev[l], ivec3(q), 0);
        n = l == 0 ? leaf_count(t.x, u_which) : t[u_which];
      }
      if (k < n || c == 7u) {
        p = q;
        break;
      }
      k -= n;
    }
  }
  uvec3 d = u_tdims[0];
  out_elem[i] = p.x + d.x * (p.y + d.y * p.z);
}
