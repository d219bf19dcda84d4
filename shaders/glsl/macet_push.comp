// Macet pass 1, the push (macet.cpp's push): one invocation per region sample; every grid vertex
// is pushed back along its edges from crossings closer than MACET_REACH, capped at
// MACET_PUSH_CAP voxels, halved until it keeps its side. Writes (displacement, f - iso).

void main() {
  uint r = invocation();
  uvec3 d = uvec3(u_region_dims);
  if (r >= d.x * d.y * d.z) return;
  ivec3 g = region_sample(r);
  if (!grid_vertex(g)) return;
  precise double f = sample_at(g) - u_iso;
  bool in0 = f >= 0.0LF;
  precise dvec3 push = dvec3(0.0LF);
  for (int a = 0; a < 3; ++a)
    for (int dir = -1; dir <= 1; dir += 2) {
      ivec3 q = g;
      q[a] += dir;
      if (q[a] < u_region_lo[a] || q[a] >= region_hi()[a]) continue;
      precise double o = sample_at(q) - u_iso;
      if ((o >= 0.0LF) == in0) continue;
      precise double t = f / (f - o);
      if (t < MACET_REACH) {
        precise double pa = push[a] - double(dir) * (MACET_REACH - t);
        push = with_component(push, a, pa);
      }
    }
  precise double len2 = push.x * push.x + push.y * push.y + push.z * push.z;
  double len = sqrt_rn(len2);
  if (len > MACET_PUSH_CAP) {
    precise double scale = MACET_PUSH_CAP / len;
    push = push * scale;
  }
  dvec3 disp = dvec3(0.0LF);
  double value = f;
  if (len > 0.0LF) try_move(g, dvec3(0.0LF), push, MACET_GUARD, disp, value);
  disp_out[r] = dvec4(disp, value);
}
