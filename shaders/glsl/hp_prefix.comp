// The number of vertices before element u_element (one invocation): how many of a brick's
// vertices precede its top plane, which the next brick lists again.
layout(std430, binding = 3) writeonly buffer Result { uint result[]; };

uniform uint u_element;

void main() {
  if (invocation() == 0u) result[0] = vertex_prefix(u_element);
}
