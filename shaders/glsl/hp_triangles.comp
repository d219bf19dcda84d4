// HistoPyramid pass 4: one invocation per output triangle, cell by cell in element order and in
// table order within a cell; its corners are vertex indices found from the vertex pyramid.
layout(std430, binding = 3) writeonly buffer Triangles { uint out_tri[]; };

uniform uint u_first;  // first triangle of this chunk
uniform uint u_count;  // triangles in this chunk

void main() {
  uint i = invocation();
  if (i >= u_count) return;
  uint k = u_first + i;
  uint e = find_element(k, 1);
  uint cs = code_of(e) & 0xffu;
  ivec3 s = element_sample(e);
  for (uint v = 0u; v < 3u; ++v) {
    ivec4 info = edge_info[tri_edge(cs, 3u * k + v)];
    uint o = element_index(s + info.xyz);
    uint below = (code_of(o) >> 8) & ((1u << uint(info.w)) - 1u);
    out_tri[3u * i + v] = vertex_prefix(o) + uint(bitCount(below));
  }
}
