// Macet in GLSL (prepended after mc_common.glsl when MACET is defined): the arithmetic of
// core/extract/macet.cpp and core/extract/macet_field.h, step for step, in double with `precise`
// (no fused multiply-adds the CPU does not do), so that every decision the CPU takes on a value
// (a move keeping its side, the guard, a halving, a cap, a tie) is taken the same way here.
//
// The uploaded region plays the CPU's view: a neighbour "in the view" is one in the region, a
// gradient is one-sided at the region's border, a point's cell is clamped to the region's cells.
// The CPU's brick contract makes emitted results independent of the view as long as it holds the
// cells grown by macet_halo(), and every region does.
//
// The constants (MACET_REACH, MACET_PUSH_CAP, MACET_SMOOTH_CAP, MACET_GUARD, MACET_SMOOTH_GUARD,
// MACET_HALVINGS, MACET_TIE_OFFSET) are defined by shaders/macet_gl.cpp from core's constexpr
// values. The Tables block holds Macet's case table (same layout as MC's).

// Per region sample, x fastest: (displacement in voxels, f - iso at the displaced point), written
// for every grid vertex (a sample with a neighbour in the region on the other side).
layout(std430, binding = 6) readonly buffer DispIn { dvec4 disp_in[]; };

ivec3 region_hi() { return u_region_lo + u_region_dims; }
bool in_region(ivec3 g) {
  return all(greaterThanEqual(g, u_region_lo)) && all(lessThan(g, region_hi()));
}
uint region_index(ivec3 g) {
  uvec3 l = uvec3(clamp(g - u_region_lo, ivec3(0), u_region_dims - 1));
  uvec3 d = uvec3(u_region_dims);
  return l.x + d.x * (l.y + d.y * l.z);
}
ivec3 region_sample(uint r) {
  uvec3 d = uvec3(u_region_dims);
  return u_region_lo + ivec3(r % d.x, (r / d.x) % d.y, r / (d.x * d.y));
}

// Field::value: f - iso of the trilinear interpolant at global point p, its cell clamped to the
// volume's and the region's cells.
double field_value(dvec3 p) {
  ivec3 gc;
  precise dvec3 u;
  for (int a = 0; a < 3; ++a) {
    int hi = max(u_region_lo[a], min(max(u_global_dims[a] - 2, 0),
                                     u_region_lo[a] + max(u_region_dims[a] - 2, 0)));
    gc[a] = clamp(int(floor(p[a])), u_region_lo[a], hi);
  }
  u = p - dvec3(gc);
  // Along an axis of one sample the clamped read gives the CPU's zero stride.
  double q0 = sample_at(gc), q1 = sample_at(gc + ivec3(1, 0, 0));
  double q2 = sample_at(gc + ivec3(0, 1, 0)), q3 = sample_at(gc + ivec3(1, 1, 0));
  double q4 = sample_at(gc + ivec3(0, 0, 1)), q5 = sample_at(gc + ivec3(1, 0, 1));
  double q6 = sample_at(gc + ivec3(0, 1, 1)), q7 = sample_at(gc + ivec3(1, 1, 1));
  precise double x00 = q0 + u.x * (q1 - q0), x10 = q2 + u.x * (q3 - q2);
  precise double x01 = q4 + u.x * (q5 - q4), x11 = q6 + u.x * (q7 - q6);
  precise double y0 = x00 + u.y * (x10 - x00), y1 = x01 + u.y * (x11 - x01);
  precise double r = y0 + u.z * (y1 - y0) - u_iso;
  return r;
}

// Field::gradient: central differences at a sample in voxel units, one-sided at the volume's and
// the region's borders.
dvec3 sample_gradient(ivec3 p) {
  dvec3 g;
  for (int a = 0; a < 3; ++a) {
    ivec3 lo = p, hi = p;
    if (p[a] > 0 && p[a] > u_region_lo[a]) lo[a] -= 1;
    if (p[a] + 1 < u_global_dims[a] && p[a] + 1 < region_hi()[a]) hi[a] += 1;
    double h = double(hi[a] - lo[a]);
    precise double d = (sample_at(hi) - sample_at(lo)) / h;
    g = with_component(g, a, h > 0.0 ? d : 0.0LF);
  }
  return g;
}

// Field::displaced: grid vertex v moved by d, inside the volume, on the border plane when v is.
dvec3 displaced(ivec3 v, dvec3 d) {
  dvec3 p;
  for (int a = 0; a < 3; ++a) {
    double x = double(v[a]);
    precise double moved = x + d[a];
    double pa = (v[a] == 0 || v[a] == u_global_dims[a] - 1)
                    ? x
                    : clamp(moved, 0.0LF, double(u_global_dims[a] - 1));
    p = with_component(p, a, pa);
  }
  return p;
}

bool sample_inside(ivec3 g) { return inside(g); }

// spreading_tie: inside sample s has two or more neighbours (in the region) outside.
bool spreading_tie(ivec3 s) {
  int outside = 0;
  for (int a = 0; a < 3; ++a)
    for (int dir = -1; dir <= 1; dir += 2) {
      ivec3 q = s;
      q[a] += dir;
      if (q[a] >= u_region_lo[a] && q[a] < region_hi()[a] && !inside(q)) ++outside;
    }
  return outside >= 2;
}

// find_root: Illinois-modified regula falsi on the trilinear interpolant along p0 -> p1.
double find_root(dvec3 p0, dvec3 p1, double f0, double f1) {
  if (p0 == p1) return 0.5LF;
  precise double lo = 0.0LF, hi = 1.0LF, flo = f0, fhi = f1;
  precise double tol = MACET_ROOT_TOLERANCE * abs(f0 - f1);
  int side = 0;
  precise double t = 0.5LF;
  for (int it = 0; it < 24; ++it) {
    precise double denom = flo - fhi;
    precise double step = (hi - lo) * flo / denom;
    precise double mid = 0.5LF * (lo + hi);
    t = denom != 0.0LF ? lo + step : mid;
    if (!(t > lo && t < hi)) t = mid;
    precise double width = hi - lo;
    if (width < MACET_ROOT_WIDTH) break;
    precise dvec3 p = p0 + t * (p1 - p0);
    double f = field_value(p);
    if (abs(f) <= tol) break;
    if ((f >= 0.0LF) == (flo >= 0.0LF)) {
      lo = t;
      flo = f;
      if (side == -1) fhi *= 0.5LF;
      side = -1;
    } else {
      hi = t;
      fhi = f;
      if (side == 1) flo *= 0.5LF;
      side = 1;
    }
  }
  return t;
}

dvec4 disp_at(ivec3 g) { return disp_in[region_index(g)]; }

// edge_crossing's end "still at the isovalue": exactly, or a tie moved to within find_root's
// tolerance of it. `f`: this end's value, `g`: the other end's. A float32 sample holding the float
// nearest the isovalue is a tie too (core/extract/macet_field.h).
bool at_tie(double f, double g, ivec3 s) {
  if (f == 0.0LF) return true;
  precise double tol = MACET_ROOT_TOLERANCE * abs(f - g);
  if (abs(f) > tol) return false;  // the sample is read only for ends this near the isovalue
  double v = sample_at(s);
#ifdef SAMPLE_F32
  return v == u_iso || v == double(u_iso_nearest);
#else
  return v == u_iso;
#endif
}

// The linear estimate of the crossing on edge (s, axis) between its displaced end points (the
// smoothing's x and t, macet.cpp's smooth_all), in global coordinates.
void linear_crossing(ivec3 s, int axis, out double t, out dvec3 x) {
  ivec3 s1 = s;
  s1[axis] += 1;
  dvec4 a = disp_at(s), b = disp_at(s1);
  precise double lin = a.w / (a.w - b.w);
  if (at_tie(a.w, b.w, s) && spreading_tie(s))
    t = MACET_TIE_OFFSET;
  else if (at_tie(b.w, a.w, s1) && spreading_tie(s1))
    t = 1.0LF - MACET_TIE_OFFSET;
  else
    t = lin;
  precise dvec3 a0 = dvec3(s) + a.xyz;
  precise dvec3 a1 = dvec3(s1) + b.xyz;
  precise dvec3 xc = a0 + t * (a1 - a0);
  x = xc;
}

// macet.cpp's crossing(): the root of the trilinear interpolant between the displaced end points
// of edge (s, axis), in global coordinates.
dvec3 macet_crossing(ivec3 s, int axis) {
  ivec3 s1 = s;
  s1[axis] += 1;
  dvec4 a = disp_at(s), b = disp_at(s1);
  precise dvec3 p0 = dvec3(s) + a.xyz;
  precise dvec3 p1 = dvec3(s1) + b.xyz;
  bool straight = all(equal(a.xyz, dvec3(0.0LF))) && all(equal(b.xyz, dvec3(0.0LF)));
  precise double t;
  if (at_tie(a.w, b.w, s) && spreading_tie(s))
    t = MACET_TIE_OFFSET;
  else if (at_tie(b.w, a.w, s1) && spreading_tie(s1))
    t = 1.0LF - MACET_TIE_OFFSET;
  else if (straight)
    t = a.w / (a.w - b.w);
  else
    t = find_root(p0, p1, a.w, b.w);
  precise dvec3 p = p0 + t * (p1 - p0);
  return p;
}

#ifdef NORMALS
// Field::world_gradient: the sample gradients interpolated trilinearly at p, in world units.
dvec3 world_gradient(dvec3 p) {
  ivec3 c;
  precise dvec3 u;
  for (int a = 0; a < 3; ++a) {
    int hi = max(u_region_lo[a], min(max(u_global_dims[a] - 2, 0),
                                     u_region_lo[a] + max(u_region_dims[a] - 2, 0)));
    c[a] = clamp(int(floor(p[a])), u_region_lo[a], hi);
  }
  u = clamp(p - dvec3(c), 0.0LF, 1.0LF);
  precise dvec3 g = dvec3(0.0LF);
  for (int corner = 0; corner < 8; ++corner) {
    int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
    ivec3 q = min(c + ivec3(dx, dy, dz), region_hi() - 1);
    precise double w = (dx != 0 ? u.x : 1.0LF - u.x) * (dy != 0 ? u.y : 1.0LF - u.y);
    w = w * (dz != 0 ? u.z : 1.0LF - u.z);
    dvec3 gc = sample_gradient(q);
    g = g + w * gc;
  }
  g = g / u_spacing;
  return g;
}
#endif

// Position (and unit normal, outward, when NORMALS) of Macet's vertex on edge (s, axis): as
// macet.cpp's fill_vertices.
void macet_edge_vertex(ivec3 s, int axis, out vec3 pos, out vec3 nrm) {
  dvec3 p = macet_crossing(s, axis);
  for (int c = 0; c < 3; ++c) {
    precise double w = u_origin[c] + u_spacing[c] * p[c];
    pos[c] = float(w);
  }
  nrm = vec3(0.0);
#ifdef NORMALS
  dvec3 g = world_gradient(p);
  precise double len2 = g.x * g.x + g.y * g.y + g.z * g.z;
  double len = sqrt_rn(len2);
  precise double inv = len > 0.0LF ? -1.0LF / len : 0.0LF;
  for (int c = 0; c < 3; ++c) {
    precise double n = g[c] * inv;
    nrm[c] = float(n);
  }
#endif
}
