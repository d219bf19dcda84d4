// HistoPyramid pass 4: the triangles, cell by cell in element order and in table order within a
// cell; their corners are vertex indices found from the vertex pyramid. main() is hp_output.glsl's.
layout(std430, binding = 3) writeonly buffer Triangles { uint out_tri[]; };

#define OUTPUT_KIND 1

// The k-th triangle of element e, at slot i.
void emit_output(uint e, uint k, uint i) {
  uint cs = code_of(e) & 0xffu;
  ivec3 s = element_sample(e);
  for (uint v = 0u; v < 3u; ++v) {
    ivec4 info = edge_info[tri_edge(cs, 3u * k + v)];
    uint o = element_index(s + info.xyz);
    uint below = (code_of(o) >> 8) & ((1u << uint(info.w)) - 1u);
    out_tri[3u * i + v] = vertex_prefix(o) + uint(bitCount(below));
  }
}
