// Benchmark only: one level (u_blevel >= 1) of the 2x2x2-block pyramid (hp_bench_block_classify.comp
// describes the layout); one invocation per stored node, padding nodes written as zero. BASE: the
// level below is the codes.
layout(std430, binding = 6) readonly buffer BlockCodes { uint bcodes[]; };
layout(std430, binding = 7) buffer BlockPyramid { uvec2 bpyr[]; };

uniform uvec3 u_bdims[17];
uniform uint u_boff[17];  // start of level l >= 1 in bpyr
uniform int u_blevel;
uniform uint u_stored;  // stored nodes of level u_blevel: 8 * |grid of u_blevel + 1|

uvec3 bcoord(uint s, int l) {
  uint q = s >> 3;
  uvec3 d = u_bdims[l + 1];
  uvec3 qc = uvec3(q % d.x, (q / d.x) % d.y, q / (d.x * d.y));
  return 2u * qc + uvec3(s & 1u, (s >> 1) & 1u, (s >> 2) & 1u);
}

void main() {
  uint s = invocation();
  if (s >= u_stored) return;
  uvec3 p = bcoord(s, u_blevel);
  uvec2 sum = uvec2(0u);
  if (all(lessThan(p, u_bdims[u_blevel]))) {
    uvec3 d = u_bdims[u_blevel];
    uint base = 8u * (p.x + d.x * (p.y + d.y * p.z));
    for (uint c = 0u; c < 8u; ++c) {
#ifdef BASE
      uint q = base + c;
      uint code = (bcodes[q >> 1] >> (16u * (q & 1u))) & 0xffffu;
      sum += uvec2(bitCount(code >> 8), tri_count(code & 0xffu));
#else
      sum += bpyr[u_boff[u_blevel - 1] + base + c];
#endif
    }
  }
  bpyr[u_boff[u_blevel] + s] = sum;
}
