// Benchmark only: the count pyramid as 3D integer textures, one per level (level 0: the 16-bit
// codes, R16UI; levels 1..L: (vertices, triangles), RG32UI, each the ceiling half of the one
// below). Written with imageStore, read with texelFetch (integer textures: no filtering). This
// pass: the codes, one invocation per element.
layout(r16ui, binding = 0) uniform writeonly uimage3D u_codes_img;

uniform uvec3 u_tdim0;

void main() {
  uint e = invocation();
  uvec3 d = u_tdim0;
  if (e >= d.x * d.y * d.z) return;
  uvec3 p = uvec3(e % d.x, (e / d.x) % d.y, e / (d.x * d.y));
  imageStore(u_codes_img, ivec3(p), uvec4(element_code(u_box_lo + ivec3(p))));
}
