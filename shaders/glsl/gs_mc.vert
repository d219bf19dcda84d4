// Geometry-shader path: one point per cell of the brick (gl_VertexID = cell index, x fastest);
// the vertex shader classifies the cell.
flat out uint v_case;
flat out uint v_index;
flat out ivec3 v_cell;

void main() {
  uvec3 d = uvec3(u_box_hi - u_box_lo);
  uint c = uint(gl_VertexID);
  v_cell = u_box_lo + ivec3(c % d.x, (c / d.x) % d.y, c / (d.x * d.y));
  v_case = cell_case(v_cell);
  v_index = c;
  gl_Position = vec4(0.0);
}
