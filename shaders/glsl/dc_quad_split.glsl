// Dual Contouring's diagonal rule (core/extract/dual_contouring.cpp's split, after
// triangle_quality's quad measure): 0-2 unless 1-3 leaves a strictly better worst triangle by
// radius ratio, computed in double from the float positions exactly as the CPU computes it.
double dc_length(vec3 p, vec3 q) {
  precise double dx = double(p.x) - double(q.x);
  precise double dy = double(p.y) - double(q.y);
  precise double dz = double(p.z) - double(q.z);
  precise double l2 = ((dx * dx) + dy * dy) + dz * dz;
  return sqrt(l2);
}
double dc_ratio(double la, double lb, double lc) {
  if (la == 0.0LF || lb == 0.0LF || lc == 0.0LF) return 0.0LF;
  precise double q = ((((lb + lc) - la) * ((lc + la) - lb)) * ((la + lb) - lc)) / ((la * lb) * lc);
  if (!(q > 0.0LF)) return 0.0LF;
  return dc_min(q, 1.0LF);
}
// Whether the quad (p0, p1, p2, p3) splits along 1-3.
bool dc_split_13(vec3 p0, vec3 p1, vec3 p2, vec3 p3) {
  double s01 = dc_length(p0, p1), s12 = dc_length(p1, p2), s23 = dc_length(p2, p3);
  double s30 = dc_length(p3, p0), d02 = dc_length(p0, p2), d13 = dc_length(p1, p3);
  double a = dc_min(dc_ratio(s12, d02, s01), dc_ratio(s23, s30, d02));
  double b = dc_min(dc_ratio(d13, s30, s01), dc_ratio(s23, d13, s12));
  return b > a;
}
