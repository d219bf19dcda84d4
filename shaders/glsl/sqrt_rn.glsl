// The correctly rounded double square root (IEEE 754's, as the CPU's std::sqrt), prepended to
// every extractor's shaders before mc_common.glsl. GLSL asks a double sqrt() for float's
// precision only; NVIDIA's (H200, driver 580) is within 2 ulp and off in 30% of the cases
// (gl_double_check), enough to flip Dual Contouring's diagonals and move Macet's and the normals'
// last bits. sqrt_rn() takes the device's sqrt() as a first guess and steps it one ulp at a time
// until it is the double nearest the true root, deciding each step exactly with +, -, * alone:
// the devices these shaders run on round those correctly (gl_double_check), while a double fma()
// is not fused on llvmpipe, so Dekker's product stands in for it.

// x in [1, 4), c in [1, 2] within a few ulp of sqrt(x): the double nearest sqrt(x).
double sqrt_rn_step(double x, double c) {
  const double u = 2.220446049250313080847263336181640625e-16LF;  // 2^-52, c's ulp in [1, 2)
  for (int i = 0; i < 8; ++i) {
    // c * c = p + pe exactly (Dekker): c split into halves of 26 bits whose products are exact.
    precise double p = c * c;
    precise double t = 134217729.0LF * c;  // 2^27 + 1
    precise double hi = t - (t - c);
    precise double lo = c - hi;
    precise double pe = ((hi * hi - p) + (2.0LF * hi) * lo) + lo * lo;
    // x - c * c = d - pe, with d exact (Sterbenz: p is within a factor of 2 of x). In units of
    // 2^-104 every term is an integer, so sqrt(x) lies above c + u / 2 exactly when
    // x - c * c > c * u, and below c - u / 2 exactly when x - c * c <= -c * u. d -+ c * u is exact
    // where it could decide the comparison (at most 2^-51 in size) and keeps its sign and
    // magnitude beyond |pe| where it is rounded.
    precise double d = x - p;
    precise double above = d - c * u;
    precise double below = d + c * u;
    if (above > pe)
      c += u;
    else if (below <= pe)
      c -= u;
    else
      break;
  }
  return c;
}

// 2^k for k in [-1022, 1023], from its bits.
double sqrt_rn_pow2(int k) { return packDouble2x32(uvec2(0u, uint(k + 1023) << 20)); }

// x (positive, finite) as xs 4^h with xs in [1, 4), exactly, from the bits of x: neither frexp()
// nor ldexp(), whose double forms a driver may implement with less care. A subnormal x is first
// made normal by 2^108.
double sqrt_rn_scale(double x, out int h) {
  int pre = 0;
  if ((unpackDouble2x32(x).y & 0x7ff00000u) == 0u) {
    x *= sqrt_rn_pow2(108);
    pre = 54;
  }
  int e = int((unpackDouble2x32(x).y >> 20) & 0x7ffu) - 1023;  // x = 1.f 2^e
  h = e >> 1;                                                   // floor(e / 2)
  double xs = x * sqrt_rn_pow2(-2 * h);
  h -= pre;
  return xs;
}

// sqrt(x) correctly rounded, for every x >= 0 (subnormals too), from a first guess of it (a
// test's), or with `guess` 0 from the device's sqrt of x scaled into [1, 4) (a normal value
// however small x is); a negative, infinite or NaN x gets the device's sqrt.
double sqrt_rn_from(double x, double guess) {
  if (!(x > 0.0LF) || isinf(x)) return x == 0.0LF ? x : sqrt(x);
  int h;
  double xs = sqrt_rn_scale(x, h);
  double c = guess > 0.0LF ? guess * sqrt_rn_pow2(-h) : sqrt(xs);
  return sqrt_rn_step(xs, clamp(c, 1.0LF, 2.0LF)) * sqrt_rn_pow2(h);
}

double sqrt_rn(double x) { return sqrt_rn_from(x, 0.0LF); }
