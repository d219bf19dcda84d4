// Benchmark only: the 2x2x2-block ("Morton per level") buffer layout of the count pyramid.
// Level l is a grid of dims u_bdims[l] (level 0: the elements, each level the ceiling half of the
// one below, up to one node); node p of level l is stored at 8 * lin(p / 2) + octant(p), lin over
// the grid of level l + 1, so a node's eight children are consecutive and a level is padded only
// to even dims. This pass: the 16-bit codes of level 0 in that order, two per word.
layout(std430, binding = 6) writeonly buffer BlockCodes { uint bcodes[]; };

uniform uvec3 u_bdims[17];
uniform uint u_words;

uvec3 bcoord(uint s, int l) {
  uint q = s >> 3;
  uvec3 d = u_bdims[l + 1];
  uvec3 qc = uvec3(q % d.x, (q / d.x) % d.y, q / (d.x * d.y));
  return 2u * qc + uvec3(s & 1u, (s >> 1) & 1u, (s >> 2) & 1u);
}

uint code_at(uint s) {
  uvec3 p = bcoord(s, 0);
  if (any(greaterThanEqual(p, u_bdims[0]))) return 0u;
  return element_code(u_box_lo + ivec3(p));
}

void main() {
  uint w = invocation();
  if (w >= u_words) return;
  bcodes[w] = code_at(2u * w) | (code_at(2u * w + 1u) << 16);
}
