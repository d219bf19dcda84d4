// Benchmark only: one level of the 3D-texture pyramid (hp_bench_tex_classify.comp): each texel
// sums the up to eight texels of the 2x2x2 block below it. BASE: the level below is the codes.
layout(binding = 0) uniform usampler3D u_src;
layout(rg32ui, binding = 1) uniform writeonly uimage3D u_dst;

uniform uvec3 u_src_dims;
uniform uvec3 u_dst_dims;

void main() {
  uint e = invocation();
  uvec3 d = u_dst_dims;
  if (e >= d.x * d.y * d.z) return;
  uvec3 p = uvec3(e % d.x, (e / d.x) % d.y, e / (d.x * d.y));
  uvec2 sum = uvec2(0u);
  for (uint c = 0u; c < 8u; ++c) {
    uvec3 q = 2u * p + uvec3(c & 1u, (c >> 1) & 1u, (c >> 2) & 1u);
    if (any(greaterThanEqual(q, u_src_dims))) continue;
    uvec4 t = texelFetch(u_src, ivec3(q), 0);
#ifdef BASE
    sum += uvec2(bitCount(t.x >> 8), tri_count(t.x & 0xffu));
#else
    sum += t.xy;
#endif
  }
  imageStore(u_dst, ivec3(p), uvec4(sum, 0u, 0u));
}
