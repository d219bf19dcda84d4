// Macet pass 2, the one smoothing pass (macet.cpp's smooth_all), a Jacobi step from the pushed
// displacements (DispIn) into DispOut: one invocation per region sample. Each grid vertex moves
// within its tangent plane by the (1 - t)-weighted mean of the umbrella Laplacians of the
// crossings on its edges. A crossing's umbrella sum is gathered here over the cells around its
// edge in the order the CPU scatters it (cell slabs of even global z first, then odd; within a
// slab y, x; triangles in table order), so every sum is added up in the CPU's order. The
// crossings' linear estimates come from macet_linear.comp.
layout(std430, binding = 8) readonly buffer Linear { dvec4 linear_in[]; };

dvec4 linear_at(ivec3 s, int axis) { return linear_in[3u * region_index(s) + uint(axis)]; }

// The MC edge number (0..11) of the edge from cell corner `o` along `axis`.
int cell_edge(ivec3 o, int axis) {
  for (int e = 0; e < 12; ++e)
    if (edge_info[e].w == axis && edge_info[e].xyz == o) return e;
  return -1;
}

void umbrella(ivec3 s, int axis, out dvec3 sum, out uint count) {
  sum = dvec3(0.0LF);
  count = 0u;
  // The four cells around the edge in (z parity, z, y, x) order: for an x or y edge, the cell
  // slab of even z first, then the other; within a slab y then x (an x edge's cells differ in y,
  // a y edge's in x, a z edge's in both).
  int z_first = axis == 2 ? 0 : ((s.z & 1) == 0 ? 0 : 1);  // subtract from z first
  for (int i = 0; i < 4; ++i) {
    ivec3 cell = s;
    if (axis == 2) {
      cell.y -= 1 - (i >> 1);
      cell.x -= 1 - (i & 1);
    } else {
      cell.z -= (i >> 1) == 0 ? z_first : 1 - z_first;
      cell[1 - axis] -= 1 - (i & 1);
    }
    if (!in_region(cell) || !in_region(cell + 1)) continue;
    uint cs = cell_case(cell);
    uint nt = tri_count(cs);
    if (nt == 0u) continue;
    int self = cell_edge(s - cell, axis);
    for (uint t = 0u; t < nt; ++t)
      for (uint v = 0u; v < 3u; ++v) {
        if (int(tri_edge(cs, 3u * t + v)) != self) continue;
        ivec4 e1 = edge_info[tri_edge(cs, 3u * t + (v + 1u) % 3u)];
        ivec4 e2 = edge_info[tri_edge(cs, 3u * t + (v + 2u) % 3u)];
        dvec3 x1 = linear_at(cell + e1.xyz, e1.w).xyz, x2 = linear_at(cell + e2.xyz, e2.w).xyz;
        precise dvec3 pair = x1 + x2;
        precise dvec3 acc = sum + pair;
        sum = acc;
        count += 2u;
      }
  }
}

void main() {
  uint r = invocation();
  uvec3 d = uvec3(u_region_dims);
  if (r >= d.x * d.y * d.z) return;
  ivec3 g = region_sample(r);
  if (!grid_vertex(g)) return;
  dvec4 old = disp_in[r];
  bool in0 = inside(g);
  precise dvec3 acc = dvec3(0.0LF);
  precise double weight = 0.0LF;
  for (int a = 0; a < 3; ++a)
    for (int dir = -1; dir <= 1; dir += 2) {
      ivec3 q = g;
      q[a] += dir;
      if (q[a] < u_region_lo[a] || q[a] >= region_hi()[a] || inside(q) == in0) continue;
      ivec3 s = dir > 0 ? g : q;
      dvec4 lin = linear_at(s, a);
      double t = lin.w;
      dvec3 x = lin.xyz, sum;
      uint count;
      umbrella(s, a, sum, count);
      precise double follow = dir > 0 ? 1.0LF - t : t;
      double wt = clamp(follow, 0.0LF, 1.0LF);
      double n = double(count);
      precise dvec3 lap = sum / n - x;
      precise dvec3 term = wt * (n > 0.0LF ? lap : dvec3(0.0LF));
      acc = acc + term;
      weight = weight + wt;
    }
  if (weight <= 0.0LF) {
    disp_out[r] = old;
    return;
  }
  acc = acc / weight;
  dvec3 gr = sample_gradient(g);
  precise double g2 = gr.x * gr.x + gr.y * gr.y + gr.z * gr.z;
  if (g2 > 0.0LF) {
    precise double along = (acc.x * gr.x + acc.y * gr.y + acc.z * gr.z) / g2;
    acc = acc - along * gr;
  }
  dvec3 from = old.xyz;
  precise dvec3 to = from + acc;
  precise double len2 = to.x * to.x + to.y * to.y + to.z * to.z;
  double len = sqrt_rn(len2);
  if (len > MACET_SMOOTH_CAP) {
    precise double scale = MACET_SMOOTH_CAP / len;
    to = to * scale;
  }
  precise dvec3 step = to - from;
  dvec3 disp = from;
  double value = old.w;
  try_move(g, from, step, MACET_SMOOTH_GUARD, disp, value);
  disp_out[r] = dvec4(disp, value);
}
