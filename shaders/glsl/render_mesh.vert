// `isotile render`'s vertex stage (mesh_render.cpp): one vertex per triangle corner, unindexed,
// so that each triangle carries its own quality and flat normal.
layout(location = 0) in vec4 a_corner;  // xyz: position relative to the view's centre; w: quality
layout(location = 1) in vec4 a_normal;  // xyz: the triangle's unit normal (world)

uniform mat4 u_view_proj;  // world (relative to the centre) -> clip, orthographic

out vec3 v_bary;  // the corner's barycentric coordinates, for the edges
flat out vec3 v_normal;
flat out float v_quality;

void main() {
  gl_Position = u_view_proj * vec4(a_corner.xyz, 1.0);
  int c = gl_VertexID % 3;
  v_bary = vec3(c == 0 ? 1.0 : 0.0, c == 1 ? 1.0 : 0.0, c == 2 ? 1.0 : 0.0);
  v_normal = a_normal.xyz;
  v_quality = a_corner.w;
}
