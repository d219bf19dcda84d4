// Dual Contouring on the geometry-shader path: one point per vertex cell of the slab (gl_VertexID
// = element index); the geometry shader emits the quads of the cell's lower corner.
flat out uint v_elem;

void main() {
  v_elem = uint(gl_VertexID);
  gl_Position = vec4(0.0);
}
