// Benchmark only: descent of the 2x2x2-block pyramid (layout: hp_bench_block_classify.comp), one
// invocation per output, writing the linear (z, y, x) index of the output's element. Outputs come
// out in the pyramid's (Morton-like) order, not in element order.
layout(std430, binding = 6) readonly buffer BlockCodes { uint bcodes[]; };
layout(std430, binding = 7) readonly buffer BlockPyramid { uvec2 bpyr[]; };
layout(std430, binding = 3) writeonly buffer BenchOut { uint out_elem[]; };

uniform uvec3 u_bdims[17];
uniform uint u_boff[17];
uniform int u_blevels;  // L: level L is one node
uniform uint u_count;
uniform int u_which;

uint blin(uvec3 p, int l) {
  uvec3 d = u_bdims[l];
  return p.x + d.x * (p.y + d.y * p.z);
}
uvec3 octant(uint c) { return uvec3(c & 1u, (c >> 1) & 1u, (c >> 2) & 1u); }

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = i;
  uvec3 p = uvec3(0u);
  for (int l = u_blevels - 1; l >= 1; --l) {
    uint base = u_boff[l] + 8u * blin(p, l + 1);
    for (uint c = 0u; c < 8u; ++c) {
      uint n = bpyr[base + c][u_which];
      if (k < n || c == 7u) {
        p = 2u * p + octant(c);
        break;
      }
      k -= n;
    }
  }
  uint base = 8u * blin(p, 1);
  for (uint c = 0u; c < 8u; ++c) {
    uint q = base + c;
    uint n = leaf_count((bcodes[q >> 1] >> (16u * (q & 1u))) & 0xffffu, u_which);
    if (k < n || c == 7u) {
      p = 2u * p + octant(c);
      break;
    }
    k -= n;
  }
  out_elem[i] = blin(p, 0);
}
