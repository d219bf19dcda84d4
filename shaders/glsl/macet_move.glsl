// The moves of Macet's grid vertices (after macet_common.glsl): macet.cpp's try_move, shared by
// the push and the smoothing passes.
layout(std430, binding = 7) writeonly buffer DispOut { dvec4 disp_out[]; };

// Whether sample g has a neighbour in the region on the other side (macet.cpp's touched_word).
bool grid_vertex(ivec3 g) {
  bool in0 = inside(g);
  for (int a = 0; a < 3; ++a)
    for (int dir = -1; dir <= 1; dir += 2) {
      ivec3 q = g;
      q[a] += dir;
      if (q[a] >= u_region_lo[a] && q[a] < region_hi()[a] && inside(q) != in0) return true;
    }
  return false;
}

// Moves grid vertex g from `from` by `step`, halving the step while the moved vertex changes
// side or ends closer than guard * |sample - iso| to the isovalue; keeps (disp, value) when no
// halving succeeds.
void try_move(ivec3 g, dvec3 from, dvec3 step, double guard, inout dvec3 disp, inout double value) {
  precise double f = sample_at(g) - u_iso;
  bool in0 = f >= 0.0LF;
  dvec3 v = dvec3(g);
  precise double need = guard * abs(f);
  for (int h = 0; h <= MACET_HALVINGS; ++h) {
    precise dvec3 to = from + step;
    dvec3 q = displaced(g, to);
    double val = field_value(q);
    if ((val >= 0.0LF) == in0 && abs(val) >= need) {
      precise dvec3 d = q - v;
      disp = d;
      value = val;
      return;
    }
    precise dvec3 halved = step * 0.5LF;
    step = halved;
  }
}
