// Geometry-shader path: emits the cell's triangles in table order, captured by transform
// feedback. Each vertex carries its edge's key within the brick (element index of the edge's lower
// sample * 3 + axis) for welding (MACET: Macet's vertex, macet_common.glsl), and its cell's index so that a capture that ran out of room can
// be resumed at a cell boundary.
layout(points) in;
layout(triangle_strip, max_vertices = 15) out;

flat in uint v_case[];
flat in uint v_index[];
flat in ivec3 v_cell[];

flat out uint tf_key;
flat out uint tf_cell;
out vec3 tf_pos;
#ifdef NORMALS
out vec3 tf_nrm;
#endif

void main() {
  uint cs = v_case[0];
  uint n = tri_count(cs);
  for (uint t = 0u; t < n; ++t) {
    for (uint v = 0u; v < 3u; ++v) {
      ivec4 info = edge_info[tri_edge(cs, 3u * t + v)];
      ivec3 s = v_cell[0] + info.xyz;
      vec3 p, nrm;
#ifdef MACET
      macet_edge_vertex(s, info.w, p, nrm);
#else
      edge_vertex(s, info.w, p, nrm);
#endif
      tf_key = element_index(s) * 3u + uint(info.w);
      tf_cell = v_index[0];
      tf_pos = p;
#ifdef NORMALS
      tf_nrm = nrm;
#endif
      EmitVertex();
    }
    EndPrimitive();
  }
}
