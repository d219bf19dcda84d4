// Macet pass 2a: the linear estimate of every crossing from the pushed end points (macet.cpp's
// smooth_all: x and t), one invocation per region sample, its +x, +y, +z edges. The smoothing
// pass reads each crossing many times; computing it once here keeps that pass short.
layout(std430, binding = 8) writeonly buffer Linear { dvec4 linear_out[]; };

void main() {
  uint r = invocation();
  uvec3 d = uvec3(u_region_dims);
  if (r >= d.x * d.y * d.z) return;
  ivec3 g = region_sample(r);
  bool in0 = inside(g);
  for (int a = 0; a < 3; ++a) {
    ivec3 q = g;
    q[a] += 1;
    if (q[a] >= region_hi()[a] || inside(q) == in0) continue;
    double t;
    dvec3 x;
    linear_crossing(g, a, t, x);
    linear_out[3u * r + uint(a)] = dvec4(x, t);
  }
}
