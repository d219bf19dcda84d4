// Shared by every Dual Contouring shader (prepended after mc_common.glsl). Follows
// core/extract/dual_contouring.cpp decision by decision, in double with `precise`, so that every
// branch the CPU takes on a value (a tie, a kink, a particle's stop, a diagonal) goes the same way.
// Defines: DC_PATCH (one vertex per patch; else one per cell), DC_PARTICLE / DC_MASS (solver),
// DC_ENO (ENO Hermite data; else central), NORMALS.
//
// Elements: the vertex cells of the slab, [u_vlo, u_vlo + u_vdims), x fastest. Element e's 16-bit
// code: the cell's MC case (bits 0-7), the crossed edges of its lower corner that get a quad
// (bits 8-10, axis a at 8 + a) and its vertex count (bits 11-13).

// The tables of core/extract/dual_contouring_table.h and dual_contouring_patches.h, uploaded from
// the CPU's constexpr arrays (dc_gl_shared.cpp).
layout(std430, binding = 7) readonly buffer DcTables {
  uint dc_patch_map[256];   // per case: the patch of each crossed edge, 2 bits per edge
  uint dc_patch_info[256];  // per case: patch count (bits 0-7), conflict faces (bits 8-13)
  uint dc_quads[48];        // per code and quad (3 per code): V' labels, 4 bits each
  uint dc_block_edge[8];    // per V': its cell edge along x, y, z, 4 bits each
  ivec4 dc_block_cell[8];   // per V': offset of its cell from the sample
};

uniform ivec3 u_vlo;      // first vertex cell of the slab (global)
uniform ivec3 u_vdims;    // vertex cells of the slab along x, y, z
uniform ivec3 u_view_lo;  // samples of the view: the CPU's bounds for gradients, lines of
uniform ivec3 u_view_hi;  // samples and the cells across faces
uniform double u_tie_offset;  // core/extract/isovalue_ties.h's kTieOffset
uniform double u_rate;        // particle_rate
uniform double u_tol2;        // particle_tolerance squared
uniform int u_steps;          // particle_steps

// std::max and std::min, NaN included (GLSL's max and min leave NaN undefined).
double dc_max(double a, double b) { return a < b ? b : a; }
double dc_min(double a, double b) { return b < a ? b : a; }

uint dc_element_count() { return uint(u_vdims.x) * uint(u_vdims.y) * uint(u_vdims.z); }
ivec3 dc_element_cell(uint e) {
  uvec3 d = uvec3(u_vdims);
  return u_vlo + ivec3(e % d.x, (e / d.x) % d.y, e / (d.x * d.y));
}
uint dc_element_index(ivec3 c) {
  uvec3 l = uvec3(c - u_vlo);
  uvec3 d = uvec3(u_vdims);
  return l.x + d.x * (l.y + d.y * l.z);
}

// ---- Patches (dual_contouring_patches.cpp) ----

// The MC edge joining corners a and b (one bit apart), from the uploaded edge table.
int dc_edge_between(int a, int b) {
  int lo = min(a, b), axis = findLSB(a ^ b);
  for (int e = 4 * axis; e < 4 * axis + 4; ++e)
    if (edge_info[e].x + 2 * edge_info[e].y + 4 * edge_info[e].z == lo) return e;
  return -1;
}

// Corner i (cyclic order) of face f: axis f / 2, side f % 2.
int dc_face_corner(int f, int i) {
  int axis = f / 2, side = f % 2, u = (axis + 1) % 3, v = (axis + 2) % 3;
  int cu = (i == 1 || i == 2) ? 1 : 0, cv = i >= 2 ? 1 : 0;
  return (cu << u) | (cv << v) | (side << axis);
}

// Twelve 4-bit fields in two words (edges 0-7, 8-11): local arrays indexed at run time become
// branch ladders on llvmpipe, which made the union-find below take seconds to compile.
uint dc_nib(uint lo, uint hi, int i) { return i < 8 ? (lo >> (4 * i)) & 15u : (hi >> (4 * (i - 8))) & 15u; }
void dc_set_nib(inout uint lo, inout uint hi, int i, uint v) {
  if (i < 8)
    lo = (lo & ~(15u << (4 * i))) | (v << (4 * i));
  else
    hi = (hi & ~(15u << (4 * (i - 8)))) | (v << (4 * (i - 8)));
}

int dc_find(uint lo, uint hi, int e) {
  for (int r = int(dc_nib(lo, hi, e)); r != e; r = int(dc_nib(lo, hi, e))) e = r;
  return e;
}
void dc_join(inout uint lo, inout uint hi, int a, int b) {
  a = dc_find(lo, hi, a);
  b = dc_find(lo, hi, b);
  if (a != b) dc_set_nib(lo, hi, max(a, b), uint(min(a, b)));
}

// The four edges of face f in cyclic order (edge i joins corners i and i + 1), 4 bits each.
uint dc_face_edges(int f) {
  uint out_edges = 0u;
  for (int i = 0; i < 4; ++i)
    out_edges |= uint(dc_edge_between(dc_face_corner(f, i), dc_face_corner(f, (i + 1) % 4))) << (4 * i);
  return out_edges;
}

// dc::cell_patches: the patch count of a cell of case cs with faces `flips` resolved the other
// way and faces `open` on the volume border; `map` gets each crossed edge's patch (2 bits each).
// Patches are numbered by their lowest edge, as on the CPU, so only the partition matters. Loops
// run over set bits (of unknown count): unrolled, they took llvmpipe seconds to compile.
uint dc_patches(uint cs, uint flips, uint open, out uint map) {
  if (flips == 0u && open == 0u) {
    map = dc_patch_map[cs];
    return dc_patch_info[cs] & 0xffu;
  }
  uint mask = case_edge_mask(cs);
  uint rlo = 0x76543210u, rhi = 0xba98u;  // every edge its own root
  uint on_border = 0u;
  for (uint fm = 63u; fm != 0u; fm &= fm - 1u) {
    int f = findLSB(fm);
    uint fe = dc_face_edges(f);
    if (((open >> f) & 1u) != 0u) {
      for (int i = 0; i < 4; ++i) on_border |= 1u << ((fe >> (4 * i)) & 15u);
      continue;
    }
    uint crossed = 0u;  // of the face's four edges
    for (int i = 0; i < 4; ++i)
      if (((mask >> ((fe >> (4 * i)) & 15u)) & 1u) != 0u) crossed |= 1u << i;
    if (bitCount(crossed) == 2) {
      int i0 = findLSB(crossed), i1 = findMSB(crossed);
      dc_join(rlo, rhi, int((fe >> (4 * i0)) & 15u), int((fe >> (4 * i1)) & 15u));
    }
    if (crossed != 15u) continue;
    bool cut_inside = ((flips >> f) & 1u) == 0u;
    for (int i = 0; i < 4; ++i) {
      // Corner i lies between edges i - 1 and i.
      bool inside = ((cs >> dc_face_corner(f, i)) & 1u) != 0u;
      if (inside == cut_inside)
        dc_join(rlo, rhi, int((fe >> (4 * ((i + 3) % 4))) & 15u), int((fe >> (4 * i)) & 15u));
    }
  }
  if (open != 0u) {
    // No crossed edge off the border: no quad, so no patch (dc::live_edges).
    if ((mask & ~on_border) == 0u) {
      map = 0u;
      return 0u;
    }
    // Pieces whose crossed edges all lie on the border join the first piece that has one off it.
    uint live = 0u;  // by root
    for (uint m = mask & ~on_border; m != 0u; m &= m - 1u)
      live |= 1u << dc_find(rlo, rhi, findLSB(m));
    int first_live = -1, first_dead = -1;
    uint dead = 0u;  // by edge
    for (uint m = mask; m != 0u; m &= m - 1u) {
      int e = findLSB(m);
      int r = dc_find(rlo, rhi, e);
      bool is_live = ((live >> r) & 1u) != 0u;
      if (!is_live) dead |= 1u << e;
      if (is_live && first_live < 0) first_live = r;
      if (!is_live && first_dead < 0) first_dead = r;
    }
    int keep = first_live >= 0 ? first_live : first_dead;
    for (uint m = dead; m != 0u; m &= m - 1u) dc_join(rlo, rhi, findLSB(m), keep);
  }
  uint nlo = 0u, nhi = 0u;  // per root: its patch + 1
  uint count = 0u;
  map = 0u;
  for (uint m = mask; m != 0u; m &= m - 1u) {
    int e = findLSB(m);
    int r = dc_find(rlo, rhi, e);
    if (dc_nib(nlo, nhi, r) == 0u) dc_set_nib(nlo, nhi, r, ++count);
    map |= ((dc_nib(nlo, nhi, r) - 1u) & 3u) << (2 * e);
  }
  return count;
}

// The MC case of global cell c, or -1 where the view lacks it (as the CPU's flips_at).
int dc_case_in_view(ivec3 c) {
  if (any(lessThan(c, u_view_lo)) || any(greaterThanEqual(c + 1, u_view_hi))) return -1;
  return int(cell_case(c));
}

// The faces of global cell c on the volume's border (dc::border_faces).
uint dc_open_faces(ivec3 c) {
  uint open = 0u;
  for (int a = 0; a < 3; ++a) {
    if (c[a] == 0) open |= 1u << (2 * a);
    if (c[a] + 2 == u_global_dims[a]) open |= 1u << (2 * a + 1);
  }
  return open;
}

// The patches of global cell c of case cs: flips from the cells across its faces, cuts at the
// border of the volume.
uint dc_cell_patches(ivec3 c, uint cs, out uint map) {
  uint flips = 0u;
  for (uint m = (dc_patch_info[cs] >> 8) & 63u; m != 0u; m &= m - 1u) {
    int f = findLSB(m);
    ivec3 d = ivec3(0);
    d[f / 2] = (f % 2) == 0 ? -1 : 1;
    int other = dc_case_in_view(c + d);
    if (other >= 0 && ((dc_patch_info[other] >> (8 + (f ^ 1))) & 1u) != 0u) flips |= 1u << f;
  }
  return dc_patches(cs, flips, dc_open_faces(c), map);
}

// Whether global cell c of case cs has a crossed edge off the volume's border (one that can get
// a quad): a cell without one gets no vertex in either vertex mode (dc::live_edges).
bool dc_has_live_edge(ivec3 c, uint cs) {
  uint open = dc_open_faces(c);
  if (open == 0u) return true;
  uint on_border = 0u;
  for (uint fm = open; fm != 0u; fm &= fm - 1u) {
    uint fe = dc_face_edges(findLSB(fm));
    for (int i = 0; i < 4; ++i) on_border |= 1u << ((fe >> (4 * i)) & 15u);
  }
  return (case_edge_mask(cs) & ~on_border) != 0u;
}

// ---- Hermite data ----

// Gradient per voxel at sample p: central differences, one-sided at the view's border (the
// CPU's gradient(); x / 2 and 0.5 x round alike).
dvec3 dc_gradient(ivec3 p) {
  dvec3 g;
  for (int a = 0; a < 3; ++a) {
    ivec3 lo = p, hi = p;
    if (p[a] > u_view_lo[a]) lo[a] -= 1;
    if (p[a] + 1 < u_view_hi[a]) hi[a] += 1;
    int h = hi[a] - lo[a];
    precise double d = sample_at(hi) - sample_at(lo);
    precise double ga = h > 0 ? d / double(h) : 0.0LF;
    g = with_component(g, a, ga);
  }
  return g;
}

// Whether an end of the edge from s0 along `axis` (values f0, f1) is a pinned tie; if so t is
// kTieOffset from it (core/extract/isovalue_ties.h).
bool dc_tie_crossing(ivec3 s0, int axis, double f0, double f1, inout double t) {
  if (f0 != u_iso && f1 != u_iso) return false;
  ivec3 s = s0;
  if (f1 == u_iso) s[axis] += 1;
  for (int a = 0; a < 3; ++a) {
    int outside = 0;
    for (int dir = -1; dir <= 1; dir += 2) {
      int g = s[a] + dir;
      if (g < 0 || g >= u_global_dims[a]) continue;
      ivec3 q = s;
      q[a] = g;
      if (sample_at(q) < u_iso) ++outside;
    }
    if (outside == 2) {
      precise double far = 1.0LF - u_tie_offset;
      t = f0 == u_iso ? u_tie_offset : far;
      return true;
    }
  }
  return false;
}

#ifdef DC_ENO
// Does the line of samples p + d e_axis, d in [lo, hi], lie in the volume and in the view?
bool dc_line_inside(ivec3 p, int axis, int lo, int hi) {
  return p[axis] + lo >= 0 && p[axis] + hi < u_global_dims[axis] &&
         p[axis] + lo >= u_view_lo[axis] && p[axis] + hi < u_view_hi[axis];
}
double dc_at(ivec3 p, int axis, int d) {
  p[axis] += d;
  return sample_at(p);
}

// The two quadratic pieces of an edge (the CPU's Pieces): a0, b0, a1, b1, e0, e1.
struct DcPieces {
  double a0, b0, a1, b1, e0, e1;
};
DcPieces dc_pieces(double fm2, double fm, double f0, double f1, double f2, double f3) {
  DcPieces q;
  precise double a0 = 0.5LF * ((f0 - 2.0LF * fm) + fm2);
  precise double b0 = (f0 - fm) + a0;
  precise double a1 = 0.5LF * ((f3 - 2.0LF * f2) + f1);
  precise double b1 = (f2 - f1) - a1;
  precise double e0 = ((f0 + b0) + a0) - f1;
  precise double e1 = ((f1 - b1) + a1) - f0;
  q.a0 = a0;
  q.b0 = b0;
  q.a1 = a1;
  q.b1 = b1;
  q.e0 = e0;
  q.e1 = e1;
  return q;
}
bool dc_kinked(DcPieces q, double rise) {
  precise double prod = q.e0 * q.e1;
  precise double lim = DC_ENO_KINK * rise;
  return !(prod < 0.0LF) && dc_max(abs(q.e0), abs(q.e1)) > lim;
}

bool dc_sign_bit(double v) { return (unpackDouble2x32(v).y & 0x80000000u) != 0u; }

// The root in [lo, hi] of a x^2 + b x + c from the non-cancelling quadratic formula.
double dc_bracketed_root(double a, double b, double c, double lo, double hi) {
  precise double disc = b * b - (4.0LF * a) * c;
  precise double root = sqrt_rn(dc_max(disc, 0.0LF));
  precise double q = -0.5LF * (b + (dc_sign_bit(b) ? -root : root));
  precise double ra = q / a;
  precise double rc = c / q;
  double r = ra >= lo && ra <= hi ? ra : rc;
  return dc_min(hi, dc_max(lo, r));
}

// One component of the ENO gradient at sample p (the CPU's eno_component).
double dc_eno_component(ivec3 p, int axis) {
  if (!dc_line_inside(p, axis, -2, 2)) return dc_gradient(p)[axis];
  double fm2 = dc_at(p, axis, -2), fm = dc_at(p, axis, -1), f0 = dc_at(p, axis, 0);
  double fp = dc_at(p, axis, 1), fp2 = dc_at(p, axis, 2);
  precise double bend_up = abs((fp2 - 2.0LF * fp) + f0);
  precise double bend_down = abs((f0 - 2.0LF * fm) + fm2);
  precise double up4 = 0.25LF * bend_up;
  precise double down4 = 0.25LF * bend_down;
  precise double right = fp - f0;
  precise double left = f0 - fm;
  if (bend_up < down4) return right;
  if (bend_down < up4) return left;
  if (dc_line_inside(p, axis, -3, 3)) {
    precise double rise = dc_max(abs(f0 - fm), abs(fp - f0));
    bool down = dc_kinked(dc_pieces(dc_at(p, axis, -3), fm2, fm, f0, fp, fp2),
                          dc_max(rise, abs(fm - fm2)));
    bool up = dc_kinked(dc_pieces(fm2, fm, f0, fp, fp2, dc_at(p, axis, 3)),
                        dc_max(rise, abs(fp2 - fp)));
    if (up != down) return up ? left : right;
  }
  precise double central = 0.5LF * (fp - fm);
  return central;
}
#endif

struct DcPlane {
  dvec3 p;
  dvec3 n;
};

// The Hermite plane of the MC edge e of cell c (whose corner values are v[]).
DcPlane dc_plane(ivec3 c, int e, double v[8]) {
  ivec4 info = edge_info[e];
  int axis = info.w;
  int c0 = info.x + 2 * info.y + 4 * info.z, c1 = c0 | (1 << axis);
  ivec3 s0 = c + info.xyz, s1 = s0;
  s1[axis] += 1;
  double f0 = v[c0], f1 = v[c1];
  precise double t = (u_iso - f0) / (f1 - f0);
  DcPlane h;
  h.p = dvec3(info.xyz);
  h.n = dvec3(0.0LF);
#ifdef DC_ENO
  precise double slope = f1 - f0;
  int side = -1;
  if (dc_tie_crossing(s0, axis, f0, f1, t)) {
  } else if (dc_line_inside(s0, axis, -2, 3)) {
    DcPieces q = dc_pieces(dc_at(s0, axis, -2), dc_at(s0, axis, -1), f0, f1, dc_at(s0, axis, 2),
                           dc_at(s0, axis, 3));
    if (dc_kinked(q, abs(f1 - f0))) {
      precise double esum = q.e0 + q.e1;
      double sgn = esum > 0.0LF ? 1.0LF : -1.0LF;
      precise double g0 = sgn * (f0 - u_iso);
      precise double g1 = sgn * (f1 - u_iso);
      precise double ga0 = sgn * q.a0, gb0 = sgn * q.b0, ga1 = sgn * q.a1, gb1 = sgn * q.b1;
      bool falling = g0 > g1;
      double t0 = dc_bracketed_root(ga0, gb0, g0, 0.0LF, 1.0LF);
      precise double t1 = 1.0LF + dc_bracketed_root(ga1, gb1, g1, -1.0LF, 0.0LF);
      precise double m0 = g1 + sgn * q.e0;
      precise double m1 = g0 + sgn * q.e1;
      bool on_p1 = falling ? !(m0 < 0.0LF && t0 < t1) : (m1 < 0.0LF && t1 > t0);
      side = on_p1 ? 1 : 0;
      t = side == 0 ? t0 : t1;
      precise double s0l = q.b0 + (2.0LF * q.a0) * t;
      precise double s1l = q.b1 + (2.0LF * q.a1) * (t - 1.0LF);
      slope = side == 0 ? s0l : s1l;
    }
  }
  h.p = with_component(h.p, axis, t);
#if defined(DC_PARTICLE) || defined(DC_QEF)
  precise dvec3 n = with_component(dvec3(0.0LF), axis, slope);
  // Across the edge: that side's end (side 0 or 1) or both ends interpolated. One call site in
  // loops of unknown length: inlined once, not six times.
  for (uint am = 7u ^ (1u << axis); am != 0u; am &= am - 1u) {
    int a = findLSB(am);
    double g0 = 0.0LF, g1 = 0.0LF;
    for (int end = side == 1 ? 1 : 0; end <= (side == 0 ? 0 : 1); ++end) {
      double g = dc_eno_component(end == 0 ? s0 : s1, a);
      if (end == 0)
        g0 = g;
      else
        g1 = g;
    }
    precise double mixed = g0 + t * (g1 - g0);
    n = with_component(n, a, side == 0 ? g0 : side == 1 ? g1 : mixed);
  }
  precise double len2 = ((n.x * n.x) + n.y * n.y) + n.z * n.z;
  double inv = len2 > 0.0LF ? 1.0LF / sqrt_rn(len2) : 0.0LF;
  h.n = n * inv;
#endif
#else
  dc_tie_crossing(s0, axis, f0, f1, t);
  h.p = with_component(h.p, axis, t);
#if defined(DC_PARTICLE) || defined(DC_QEF)
  dvec3 g0 = dc_gradient(s0), g1 = dc_gradient(s1);
  precise dvec3 n = g0 + t * (g1 - g0);
  precise double len2 = ((n.x * n.x) + n.y * n.y) + n.z * n.z;
  double inv = len2 > 0.0LF ? 1.0LF / sqrt_rn(len2) : 0.0LF;
  h.n = n * inv;
#endif
#endif
  return h;
}

// ---- Placement (dc::accumulate, dc::run_particles) ----

double dc_clamp01(double v) { return dc_min(1.0LF, dc_max(0.0LF, v)); }

#ifdef DC_QEF
// dc::solve_qef: the QEF's least squares about the mass point over the eigen directions whose
// eigenvalue is above u_qef_cutoff of the largest, from dc::symmetric_eigen's Jacobi sweeps
// (core/extract/dual_contouring.cpp), step for step.
uniform double u_qef_cutoff;
uniform int u_jacobi_sweeps;

dvec3 dc_solve_qef(dvec3 mass, dmat3 A, dvec3 b) {
  // m[c][r] = A's row r, column c; v's columns are the eigenvectors.
  precise dmat3 m = A;
  precise dmat3 v = dmat3(1.0LF);
  for (int sweep = 0; sweep < u_jacobi_sweeps; ++sweep) {
    bool rotated = false;
    for (int pair = 0; pair < 3; ++pair) {
      int p = pair == 2 ? 1 : 0, q = pair == 0 ? 1 : 2;
      double apq = m[q][p];
      precise double negligible = DC_JACOBI_NEGLIGIBLE * (abs(m[p][p]) + abs(m[q][q]));
      if (!(abs(apq) > negligible)) continue;
      rotated = true;
      precise double theta = (m[q][q] - m[p][p]) / (2.0LF * apq);
      // The roots' arguments in precise variables of their own: `precise` need not reach into a
      // call's argument, and a fused theta * theta + 1 is not the CPU's value.
      precise double theta2 = theta * theta + 1.0LF;
      precise double t = 1.0LF / (abs(theta) + sqrt_rn(theta2));
      if (theta < 0.0LF) t = -t;
      precise double t2 = t * t + 1.0LF;
      precise double c = 1.0LF / sqrt_rn(t2);
      precise double s = t * c;
      for (int k = 0; k < 3; ++k) {  // columns p and q
        precise double mkp = m[p][k], mkq = m[q][k];
        precise double np = c * mkp - s * mkq, nq = s * mkp + c * mkq;
        m = with_element(m, p, k, np);
        m = with_element(m, q, k, nq);
      }
      for (int k = 0; k < 3; ++k) {  // rows p and q
        precise double mpk = m[k][p], mqk = m[k][q];
        precise double np = c * mpk - s * mqk, nq = s * mpk + c * mqk;
        m = with_element(m, k, p, np);
        m = with_element(m, k, q, nq);
      }
      for (int k = 0; k < 3; ++k) {
        precise double vkp = v[p][k], vkq = v[q][k];
        precise double np = c * vkp - s * vkq, nq = s * vkp + c * vkq;
        v = with_element(v, p, k, np);
        v = with_element(v, q, k, nq);
      }
    }
    if (!rotated) break;
  }
  // Ascending eigenvalues: a three-element sort by the CPU's comparisons.
  int order[3] = int[3](0, 1, 2);
  double lambda[3] = double[3](m[0][0], m[1][1], m[2][2]);
  if (lambda[order[1]] < lambda[order[0]]) { int x = order[0]; order[0] = order[1]; order[1] = x; }
  if (lambda[order[2]] < lambda[order[1]]) { int x = order[1]; order[1] = order[2]; order[2] = x; }
  if (lambda[order[1]] < lambda[order[0]]) { int x = order[0]; order[0] = order[1]; order[1] = x; }
  precise dvec3 residual = b - ((A[0] * mass[0] + A[1] * mass[1]) + A[2] * mass[2]);
  precise dvec3 x = mass;
  double largest = lambda[order[2]];
  precise double floor_value = u_qef_cutoff * largest;
  if (largest > 0.0LF)
    for (int i = 0; i < 3; ++i) {
      double l = lambda[order[i]];
      if (!(l > floor_value && l > 0.0LF)) continue;
      dvec3 u = v[order[i]];
      precise double d = ((u[0] * residual[0] + u[1] * residual[1]) + u[2] * residual[2]) / l;
      x = x + u * d;
    }
  return dvec3(dc_clamp01(x[0]), dc_clamp01(x[1]), dc_clamp01(x[2]));
}
#endif

// The dual vertex (cell-local) of the crossed edges `edges` of cell c.
dvec3 dc_place(ivec3 c, uint edges) {
  double v[8];
  for (int k = 0; k < 8; ++k) v[k] = sample_at(c + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1));
  precise dvec3 mass = dvec3(0.0LF);
  precise dmat3 A = dmat3(0.0LF);  // A[col][row]
  precise dvec3 b = dvec3(0.0LF);
  int count = 0;
  // Over the set bits, in ascending order as the CPU sums them; a loop of unknown length is not
  // unrolled (twelve inlined copies of dc_plane made llvmpipe compile for seconds).
  for (uint m = edges; m != 0u; m &= m - 1u) {
    int e = findLSB(m);
    DcPlane h = dc_plane(c, e, v);
    ++count;
    mass += h.p;
#if defined(DC_PARTICLE) || defined(DC_QEF)
    precise double d = ((h.n.x * h.p.x) + h.n.y * h.p.y) + h.n.z * h.p.z;
    b += h.n * d;
    // A[k][r] += n[r] n[k]: column k gains n n[k] (constant column indices).
    A[0] += h.n * h.n.x;
    A[1] += h.n * h.n.y;
    A[2] += h.n * h.n.z;
#endif
  }
  mass /= double(count);
#ifdef DC_QEF
  return dc_solve_qef(mass, A, b);
#elif defined(DC_PARTICLE)
  // x <- clamp(x + c (b - A x)) as the affine map (I - c A) x + c b, stopping once a step moves
  // less than the tolerance (measured after the clamp).
  precise dvec3 shift = u_rate * b;
  // M[k][r] = (r == k ? 1 : 0) - u_rate A[k][r], element by element.
  precise dmat3 M = dmat3(1.0LF) - u_rate * A;
  precise dvec3 x = mass;
  for (int step = 0; step < u_steps; ++step) {
    precise dvec3 next;
    precise double moved2 = 0.0LF;
    for (int r = 0; r < 3; ++r) {
      precise double y = ((M[0][r] * x[0] + M[1][r] * x[1]) + M[2][r] * x[2]) + shift[r];
      next = with_component(next, r, dc_clamp01(y));
      moved2 += (next[r] - x[r]) * (next[r] - x[r]);
    }
    x = next;
    if (moved2 < u_tol2) break;
  }
  return x;
#else
  return mass;
#endif
}

// The outward unit normal at cell-local x of cell c, in world units (the CPU's vertex_normal).
vec3 dc_vertex_normal(ivec3 c, dvec3 x) {
  precise dvec3 n = dvec3(0.0LF);
  for (uint km = 255u; km != 0u; km &= km - 1u) {  // corners in order; not unrolled
    int k = findLSB(km);
    dvec3 g = dc_gradient(c + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1));
    precise double w = 1.0LF;
    for (int a = 0; a < 3; ++a) w *= ((k >> a) & 1) != 0 ? x[a] : 1.0LF - x[a];
    n -= (w * g) / u_spacing;
  }
  precise double len2 = ((n.x * n.x) + n.y * n.y) + n.z * n.z;
  double inv = len2 > 0.0LF ? 1.0LF / sqrt_rn(len2) : 0.0LF;
  return vec3(n * inv);
}

// The world position of cell-local x in global cell c, rounded to float at the end.
vec3 dc_position(ivec3 c, dvec3 x) {
  vec3 p;
  for (int a = 0; a < 3; ++a) {
    precise double w = u_origin[a] + u_spacing[a] * (double(c[a]) + x[a]);
    p[a] = float(w);
  }
  return p;
}
