#include "core/volume/procedural_fields.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <charconv>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "core/errors.h"

namespace isotile {
namespace {

using std::numbers::pi;

constexpr double kInf = std::numeric_limits<double>::infinity();

constexpr std::array<FieldKind, 5> kKinds = {FieldKind::Sphere, FieldKind::Torus, FieldKind::Gyroid,
                                             FieldKind::CsgBox, FieldKind::MarschnerLobb};

constexpr double kSphereRadius = 0.75;
constexpr double kTorusMajor = 0.5;
constexpr double kTorusMinor = 0.2;
constexpr double kGyroidW = 2 * pi;
constexpr double kBoxHalf = 0.6;
constexpr double kBallRadius = 0.5;
constexpr Vec3d kBallCentre = {0.6, 0.6, 0.6};
constexpr double kMlFm = 6;
constexpr double kMlAlpha = 0.25;

Vec3d sub(const Vec3d& a, const Vec3d& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
Vec3d add(const Vec3d& a, const Vec3d& b) {
  return {a[0] + b[0], a[1] + b[1], a[2] + b[2]};
}
Vec3d scale(const Vec3d& a, double s) {
  return {a[0] * s, a[1] * s, a[2] * s};
}
double norm(const Vec3d& a) {
  return std::sqrt(dot(a, a));
}

std::string known_names() {
  std::string s;
  for (FieldKind k : kKinds) {
    if (!s.empty()) s += ", ";
    s += field_name(k);
  }
  return s;
}

double box_sdf(const Vec3d& u) {
  double outside2 = 0, inside = -kInf;
  for (int a = 0; a < 3; ++a) {
    const double q = std::abs(u[a]) - kBoxHalf;
    if (q > 0) outside2 += q * q;
    inside = std::max(inside, q);
  }
  return std::sqrt(outside2) + std::min(inside, 0.0);
}

// ---- Smooth fields: value and analytic derivatives, for the Newton projection. ----

using Mat3 = std::array<Vec3d, 3>;

double gyroid_value(const Vec3d& u) {
  const double x = kGyroidW * u[0], y = kGyroidW * u[1], z = kGyroidW * u[2];
  return std::sin(x) * std::cos(y) + std::sin(y) * std::cos(z) + std::sin(z) * std::cos(x);
}

Vec3d gyroid_grad(const Vec3d& u) {
  const double x = kGyroidW * u[0], y = kGyroidW * u[1], z = kGyroidW * u[2];
  const double sx = std::sin(x), cx = std::cos(x), sy = std::sin(y), cy = std::cos(y);
  const double sz = std::sin(z), cz = std::cos(z);
  return {kGyroidW * (cx * cy - sz * sx), kGyroidW * (cy * cz - sx * sy),
          kGyroidW * (cz * cx - sy * sz)};
}

Mat3 gyroid_hess(const Vec3d& u) {
  const double x = kGyroidW * u[0], y = kGyroidW * u[1], z = kGyroidW * u[2];
  const double sx = std::sin(x), cx = std::cos(x), sy = std::sin(y), cy = std::cos(y);
  const double sz = std::sin(z), cz = std::cos(z);
  const double w2 = kGyroidW * kGyroidW;
  const double xy = -w2 * cx * sy, yz = -w2 * cy * sz, xz = -w2 * sx * cz;
  return {Vec3d{-w2 * (sx * cy + sz * cx), xy, xz}, Vec3d{xy, -w2 * (sy * cz + sx * cy), yz},
          Vec3d{xz, yz, -w2 * (sz * cx + sy * cz)}};
}

double ml_value(const Vec3d& u) {
  const double r = std::hypot(u[0], u[1]);
  const double rho_r = std::cos(2 * pi * kMlFm * std::cos(pi * r / 2));
  return (1 - std::sin(pi * u[2] / 2) + kMlAlpha * (1 + rho_r)) / (2 * (1 + kMlAlpha));
}

Vec3d ml_grad(const Vec3d& u) {
  const double r = std::hypot(u[0], u[1]);
  // sin(pi r / 2) / r stays finite on the z axis, where the field is smooth but x/r is not.
  const double sinc = r < 1e-8 ? pi / 2 : std::sin(pi * r / 2) / r;
  const double d_rho_r_over_r = std::sin(2 * pi * kMlFm * std::cos(pi * r / 2)) * pi * kMlFm * pi *
                                sinc;  // (d rho_r / dr) / r
  const double k = 1 / (2 * (1 + kMlAlpha));
  return {k * kMlAlpha * d_rho_r_over_r * u[0], k * kMlAlpha * d_rho_r_over_r * u[1],
          -k * (pi / 2) * std::cos(pi * u[2] / 2)};
}

Mat3 ml_hess(const Vec3d& u) {
  const double r = std::hypot(u[0], u[1]);
  const double k = kMlAlpha / (2 * (1 + kMlAlpha));  // scale of the radial term
  const double phi = 2 * pi * kMlFm * std::cos(pi * r / 2);
  const double sinc = r < 1e-8 ? pi / 2 : std::sin(pi * r / 2) / r;
  // rho_r(r) = cos(phi(r)); g1 = rho_r' / r, g2 = rho_r''.
  const double g1 = std::sin(phi) * pi * pi * kMlFm * sinc;
  const double dphi = -pi * pi * kMlFm * std::sin(pi * r / 2);
  const double ddphi = -(pi * pi * pi / 2) * kMlFm * std::cos(pi * r / 2);
  const double g2 = -std::cos(phi) * dphi * dphi - std::sin(phi) * ddphi;
  // Hessian of a radial function: g1 I + (g2 - g1) rhat rhat^T; on the axis g2 = g1.
  const double c = r < 1e-8 ? 0.0 : (g2 - g1) / (r * r);
  const double zz = (1 / (2 * (1 + kMlAlpha))) * (pi / 2) * (pi / 2) * std::sin(pi * u[2] / 2);
  const double xy = k * c * u[0] * u[1];
  return {Vec3d{k * (g1 + c * u[0] * u[0]), xy, 0}, Vec3d{xy, k * (g1 + c * u[1] * u[1]), 0},
          Vec3d{0, 0, zz}};
}

// The 26 unit directions to the neighbours of a grid cell: a cheap, even spread of search starts.
const std::array<Vec3d, 26>& neighbour_directions() {
  static const std::array<Vec3d, 26> dirs = [] {
    std::array<Vec3d, 26> d{};
    int i = 0;
    for (int x = -1; x <= 1; ++x)
      for (int y = -1; y <= 1; ++y)
        for (int z = -1; z <= 1; ++z)
          if (x != 0 || y != 0 || z != 0)
            d[i++] = scale(Vec3d{double(x), double(y), double(z)},
                           1 / std::sqrt(double(x * x + y * y + z * z)));
    return d;
  }();
  return dirs;
}

struct Smooth {
  double (*value)(const Vec3d&);
  Vec3d (*grad)(const Vec3d&);
  Mat3 (*hess)(const Vec3d&);
  double iso;
  double hess_bound;  // a bound on the Hessian's spectral norm over all of space
};

// Gershgorin on gyroid_hess: a diagonal entry is at most 2 w^2, an off-diagonal one w^2.
constexpr double kGyroidHessBound = 4 * kGyroidW * kGyroidW;

// ml_hess's eigenvalues: k g1 and k g2 in the xy block (|sinc| <= pi / 2, |dphi| <= pi^2 fm,
// |ddphi| <= pi^3 fm / 2, so |g1| <= pi^3 fm / 2 <= |g2|'s bound), and zz.
constexpr double kMlHessBound =
    std::max(kMlAlpha / (2 * (1 + kMlAlpha)) *
                 (pi * pi * pi * pi * kMlFm * kMlFm + pi * pi * pi * kMlFm / 2),
             0.125 * pi * pi / (1 + kMlAlpha));

// A cap on one Newton step, in normalised units, well under the fields' feature sizes (gyroid
// period 1, Marschner-Lobb radial ripples about 0.1), so a far or nearly flat start walks towards
// the nearby sheet instead of jumping across several.
constexpr double kMaxStep = 0.02;

// Newton projection onto f = iso along the gradient. False when it meets a vanishing gradient or
// does not converge.
bool newton_project(const Smooth& f, Vec3d x, Vec3d& out) {
  for (int it = 0; it < 200; ++it) {
    const double r = f.value(x) - f.iso;
    if (std::abs(r) <= 1e-14) {
      out = x;
      return true;
    }
    const Vec3d g = f.grad(x);
    const double g2 = dot(g, g);
    if (!(g2 > 1e-20)) return false;
    Vec3d step = scale(g, r / g2);
    const double len = norm(step);
    if (len > kMaxStep) step = scale(step, kMaxStep / len);
    x = sub(x, step);
    // Rounding in the field bounds |r| from below; a step this small means we are there.
    if (len <= 1e-15 * (1 + norm(x))) {
      if (std::abs(f.value(x) - f.iso) > 1e-10) return false;
      out = x;
      return true;
    }
  }
  if (std::abs(f.value(x) - f.iso) > 1e-10) return false;
  out = x;
  return true;
}

// Moves the surface point x towards the foot of the perpendicular from p (the fixed point has
// p - x along the normal) by Newton steps on the distance over the surface: with h = (p - x) . n,
// t the tangential part of p - x and the surface locally x + v - (v^T H v / 2|g|) n, the squared
// distance is about |v - t|^2 + h^2 + h v^T H v / |g|, minimised by (I + h H_T / |g|) v = t in the
// tangent plane. Past a focal point that system is not positive definite and the plain tangential
// step t is used instead. A step that does not bring the re-projected point closer is halved, so
// each accepted round is a surface point strictly closer to p and the result is never worse than
// the plain Newton foot.
double refine_foot_point(const Smooth& f, const Vec3d& p, Vec3d x) {
  double best = norm(sub(x, p));
  for (int it = 0; it < 100 && best > 0; ++it) {
    const Vec3d g = f.grad(x);
    const double gl = norm(g);
    if (!(gl > 1e-10)) break;
    const Vec3d n = scale(g, 1 / gl);
    const Vec3d px = sub(p, x);
    const double h = dot(px, n);
    const Vec3d t = sub(px, scale(n, h));
    const double tl = norm(t);
    if (tl <= 1e-16 * (1 + norm(x))) break;
    const Vec3d e1 = scale(t, 1 / tl);
    const Vec3d e2 = {n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2],
                      n[0] * e1[1] - n[1] * e1[0]};
    const Mat3 hm = f.hess(x);
    auto form = [&](const Vec3d& a, const Vec3d& b) {
      return dot(a, {dot(hm[0], b), dot(hm[1], b), dot(hm[2], b)});
    };
    const double a11 = 1 + h * form(e1, e1) / gl, a12 = h * form(e1, e2) / gl;
    const double a22 = 1 + h * form(e2, e2) / gl;
    const double det = a11 * a22 - a12 * a12;
    Vec3d step = t;
    if (a11 > 0 && det > 0) step = add(scale(e1, tl * a22 / det), scale(e2, -tl * a12 / det));
    bool improved = false;
    const double before = best;
    for (double a = 1; a > 1e-3 && !improved; a *= 0.5) {
      Vec3d x2;
      if (!newton_project(f, add(x, scale(step, a)), x2)) continue;
      const double d2 = norm(sub(x2, p));
      if (d2 < best) {
        best = d2;
        x = x2;
        improved = true;
      }
    }
    if (!improved || before - best <= 1e-16 * (1 + best)) break;
  }
  return best;
}

// Fallback when Newton from p itself fails (p at or near a critical point of the field): march
// rays in 26 directions to the first sign change, bisect, and refine the best hit. Slow, but only
// reached at isolated points.
double ray_search_distance(const Smooth& f, const Vec3d& p) {
  const double f0 = f.value(p) - f.iso;
  if (f0 == 0) return 0;
  double best = kInf;
  Vec3d best_x{};
  constexpr double kStep = 0.005, kMaxLen = 3;
  for (const Vec3d& dir : neighbour_directions()) {
    double t0 = 0;
    for (double t = kStep; t <= kMaxLen && t < best; t += kStep) {
      if ((f.value(add(p, scale(dir, t))) - f.iso) * f0 > 0) {
        t0 = t;
        continue;
      }
      double lo = t0, hi = t;
      for (int b = 0; b < 100 && hi - lo > 1e-16; ++b) {
        const double mid = 0.5 * (lo + hi);
        if ((f.value(add(p, scale(dir, mid))) - f.iso) * f0 > 0)
          lo = mid;
        else
          hi = mid;
      }
      Vec3d x = add(p, scale(dir, hi));
      Vec3d polished;
      if (newton_project(f, x, polished)) x = polished;
      const double d = norm(sub(x, p));
      if (d < best) {
        best = d;
        best_x = x;
      }
      break;
    }
  }
  if (best == kInf) return kInf;
  return refine_foot_point(f, p, best_x);
}

// Newton from p finds a local foot point, not always the nearest: in the Marschner-Lobb rim
// ripples the nearest point can be on the next ripple. The nearest point lies within the first
// foot's distance, so restarting from the 26 directions on that sphere reaches its basin in the
// cases the tests probe. Every candidate is an actual surface point, so the result is an upper
// bound on the distance and exact whenever one start lands in the nearest point's basin.
//
// The restarts are skipped where they cannot find anything nearer. Within the ball of radius d
// (the foot's distance) around p the gradient differs from g = grad f(p) by at most L d (L bounds
// the Hessian's norm). With L d <= |g| / 8, f grows by at least 7/8 |g| per unit along g
// throughout the ball, so its zero set there is a single sheet, a graph over the plane normal to
// g, whose curvature (at most 8 L / 7 |g|, below 1 / (7 d)) is too small for the distance from p
// to have a second local minimum on it: the refined foot is the nearest point of the whole
// surface. Mesh vertices lie within a fraction of a voxel of the surface, where this holds almost
// everywhere, and it is what keeps `--stats` on procedural fields fast.
double smooth_distance(const Smooth& f, const Vec3d& p) {
  Vec3d x;
  double best = newton_project(f, p, x) ? refine_foot_point(f, p, x) : ray_search_distance(f, p);
  if (!(best > 0) || !std::isfinite(best)) return best;
  if (8 * f.hess_bound * best <= norm(f.grad(p))) return best;
  const double radius = best;
  for (const Vec3d& dir : neighbour_directions())
    if (newton_project(f, add(p, scale(dir, radius)), x))
      best = std::min(best, refine_foot_point(f, p, x));
  return best;
}

// ---- csg-box: exact distance to the boundary of (box minus ball). ----

using Vec2d = std::array<double, 2>;

// Distance in a plane from q to R = square [-h, h]^2 minus the open disk (dc, rd) (no disk when
// rd < 0). The boundary of R is made of the square's edges outside the disk and the circle inside
// the square. The distance to a circle point is unimodal in its angle, so on any arc the minimum
// is the radial foot or an arc endpoint, and arc endpoints are endpoints of the clipped edges.
double distance_to_face_region(const Vec2d& q, double h, const Vec2d& dc, double rd) {
  const bool has_disk = rd >= 0;
  const Vec2d v = {q[0] - dc[0], q[1] - dc[1]};
  const double vlen = std::hypot(v[0], v[1]);
  const bool in_square = std::abs(q[0]) <= h && std::abs(q[1]) <= h;
  if (in_square && (!has_disk || vlen >= rd)) return 0;

  double best = kInf;
  const std::array<Vec2d, 4> corners = {Vec2d{-h, -h}, Vec2d{h, -h}, Vec2d{h, h}, Vec2d{-h, h}};
  for (int e = 0; e < 4; ++e) {
    const Vec2d a = corners[e], b = corners[(e + 1) % 4];
    const Vec2d d = {b[0] - a[0], b[1] - a[1]};
    const double dd = d[0] * d[0] + d[1] * d[1];
    std::array<std::array<double, 2>, 2> pieces{};
    int count = 0;
    double disc = -1, qa = 0, qb = 0;
    if (has_disk) {
      const Vec2d ac = {a[0] - dc[0], a[1] - dc[1]};
      qa = 2 * (d[0] * ac[0] + d[1] * ac[1]);
      qb = ac[0] * ac[0] + ac[1] * ac[1] - rd * rd;
      disc = qa * qa - 4 * dd * qb;
    }
    if (disc > 0) {
      const double s = std::sqrt(disc);
      const double t1 = (-qa - s) / (2 * dd), t2 = (-qa + s) / (2 * dd);
      if (t1 > 0) pieces[count++] = {0, std::min(1.0, t1)};
      if (t2 < 1) pieces[count++] = {std::max(0.0, t2), 1};
    } else {
      pieces[count++] = {0, 1};
    }
    const double t_free = ((q[0] - a[0]) * d[0] + (q[1] - a[1]) * d[1]) / dd;
    for (int i = 0; i < count; ++i) {
      const double t = std::clamp(t_free, pieces[i][0], pieces[i][1]);
      best = std::min(best, std::hypot(q[0] - (a[0] + t * d[0]), q[1] - (a[1] + t * d[1])));
    }
  }
  if (has_disk) {
    // At the centre every circle point is equally near; any direction will do.
    const Vec2d dir = vlen > 0 ? Vec2d{v[0] / vlen, v[1] / vlen} : Vec2d{1, 0};
    const Vec2d s = {dc[0] + rd * dir[0], dc[1] + rd * dir[1]};
    if (std::abs(s[0]) <= h && std::abs(s[1]) <= h) best = std::min(best, std::abs(vlen - rd));
  }
  return best;
}

double csg_box_distance(const Vec3d& p) {
  double best = kInf;
  // The sphere patch inside the box. The radial foot is the nearest sphere point; when it falls
  // outside the box the patch's nearest point is on its rim, which lies on the faces' circles.
  const Vec3d v = sub(p, kBallCentre);
  const double vlen = norm(v);
  const Vec3d dir = vlen > 0 ? scale(v, 1 / vlen) : scale(Vec3d{-1, -1, -1}, 1 / std::sqrt(3.0));
  const Vec3d s = add(kBallCentre, scale(dir, kBallRadius));
  if (std::abs(s[0]) <= kBoxHalf && std::abs(s[1]) <= kBoxHalf && std::abs(s[2]) <= kBoxHalf)
    best = std::abs(vlen - kBallRadius);

  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    for (double side : {-kBoxHalf, kBoxHalf}) {
      const double height = p[a] - side;
      const double off = kBallCentre[a] - side;
      const double rd =
          std::abs(off) < kBallRadius ? std::sqrt(kBallRadius * kBallRadius - off * off) : -1.0;
      const double d2 =
          distance_to_face_region({p[b], p[c]}, kBoxHalf, {kBallCentre[b], kBallCentre[c]}, rd);
      best = std::min(best, std::hypot(height, d2));
    }
  }
  return best;
}

}  // namespace

std::string_view field_name(FieldKind kind) {
  switch (kind) {
    case FieldKind::Sphere:
      return "sphere";
    case FieldKind::Torus:
      return "torus";
    case FieldKind::Gyroid:
      return "gyroid";
    case FieldKind::CsgBox:
      return "csg-box";
    case FieldKind::MarschnerLobb:
      return "marschner-lobb";
  }
  return "unknown";
}

std::vector<std::string_view> field_names() {
  std::vector<std::string_view> names;
  for (FieldKind k : kKinds) names.push_back(field_name(k));
  return names;
}

double field_default_iso(FieldKind kind) {
  return kind == FieldKind::MarschnerLobb ? 0.5 : 0.0;
}

std::optional<FieldSpec> parse_field_spec(std::string_view input) {
  constexpr std::string_view kPrefix = "field:";
  if (!input.starts_with(kPrefix)) return std::nullopt;
  // Built by append: GCC 12 warns falsely (-Wrestrict) on "'" + std::string at -O2.
  std::string quoted(1, '\'');
  quoted.append(input).push_back('\'');
  const std::string_view rest = input.substr(kPrefix.size());
  const auto colon = rest.find(':');
  if (colon == std::string_view::npos)
    throw InputError("field spec " + quoted + " must be field:NAME:N, e.g. field:sphere:64");
  const std::string_view name = rest.substr(0, colon);
  const std::string_view count = rest.substr(colon + 1);

  std::optional<FieldKind> kind;
  for (FieldKind k : kKinds)
    if (field_name(k) == name) kind = k;
  if (!kind)
    throw InputError("unknown field '" + std::string(name) + "' in " + quoted +
                     "; known fields: " + known_names());

  std::int64_t n = 0;
  const auto [ptr, ec] = std::from_chars(count.data(), count.data() + count.size(), n);
  if (ec == std::errc::result_out_of_range && ptr == count.data() + count.size() &&
      !count.starts_with('-'))
    throw InputError("field size '" + std::string(count) + "' in " + quoted + " is too large");
  if (ec != std::errc() || ptr != count.data() + count.size() || n <= 0)
    throw InputError("field size '" + std::string(count) + "' in " + quoted +
                     " is not a positive integer");
  if (n < 2)
    throw InputError("field size in " + quoted + " must be at least 2, got " + std::to_string(n));
  try {
    checked_volume_bytes(ScalarType::Float32, {n, n, n});
  } catch (const CapacityError& e) {
    throw InputError("field size " + std::to_string(n) + " in " + quoted +
                     " is too large: " + e.what());
  }
  return FieldSpec{*kind, n};
}

double field_value(FieldKind kind, const Vec3d& u) {
  switch (kind) {
    case FieldKind::Sphere:
      return kSphereRadius - norm(u);
    case FieldKind::Torus:
      return kTorusMinor - std::hypot(std::hypot(u[0], u[1]) - kTorusMajor, u[2]);
    case FieldKind::Gyroid:
      return gyroid_value(u);
    case FieldKind::CsgBox: {
      const double d_ball = norm(sub(u, kBallCentre)) - kBallRadius;
      return -std::max(box_sdf(u), -d_ball);
    }
    case FieldKind::MarschnerLobb:
      return ml_value(u);
  }
  return 0;
}

void fill_field_box(const FieldSpec& spec, const Box3& box, float* out) {
  const std::int64_t n = spec.n;
  // One sample per axis leaves the normalised coordinate undefined (0/0).
  if (n < 2) throw InputError("field size must be at least 2, got " + std::to_string(n));
  const double denom = static_cast<double>(n - 1);
  auto coord = [denom](std::int64_t g) { return 2.0 * static_cast<double>(g) / denom - 1.0; };
  const std::int64_t nx = box.extent(0), ny = box.extent(1);
  if (spec.kind == FieldKind::Gyroid) {
    // Separable: the sines and cosines of each coordinate once per axis, then gyroid_value's
    // products and sums in its order, so the samples are the same bits at a fraction of the cost.
    std::array<std::vector<double>, 3> sn, cs;
    for (int a = 0; a < 3; ++a)
      for (std::int64_t g = box.lo[a]; g < box.hi[a]; ++g) {
        sn[a].push_back(std::sin(kGyroidW * coord(g)));
        cs[a].push_back(std::cos(kGyroidW * coord(g)));
      }
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, box.extent(2)), [&](const auto& range) {
      for (std::int64_t k = range.begin(); k != range.end(); ++k)
        for (std::int64_t j = 0; j < ny; ++j) {
          float* row = out + (k * ny + j) * nx;
          for (std::int64_t i = 0; i < nx; ++i)
            row[i] =
                static_cast<float>(sn[0][i] * cs[1][j] + sn[1][j] * cs[2][k] + sn[2][k] * cs[0][i]);
        }
    });
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(box.lo[2], box.hi[2]), [&](const auto& range) {
    for (std::int64_t k = range.begin(); k != range.end(); ++k) {
      const double z = coord(k);
      for (std::int64_t j = box.lo[1]; j < box.hi[1]; ++j) {
        const double y = coord(j);
        float* row = out + ((k - box.lo[2]) * ny + (j - box.lo[1])) * nx;
        for (std::int64_t i = box.lo[0]; i < box.hi[0]; ++i)
          row[i - box.lo[0]] = static_cast<float>(field_value(spec.kind, {coord(i), y, z}));
      }
    }
  });
}

Volume make_field_volume(const FieldSpec& spec) {
  if (spec.n < 2) throw InputError("field size must be at least 2, got " + std::to_string(spec.n));
  Volume vol(ScalarType::Float32, {spec.n, spec.n, spec.n});
  fill_field_box(spec, {{0, 0, 0}, {spec.n, spec.n, spec.n}}, vol.data<float>());
  return vol;
}

double distance_voxels(const FieldSpec& spec, const Vec3d& p) {
  // Normalised coordinates are a uniform scaling of voxel coordinates, so distances (and the
  // Newton projection, which is scale-covariant) carry over by the factor alone.
  assert(spec.n >= 2);
  const double denom = static_cast<double>(spec.n - 1);
  const Vec3d u = {2 * p[0] / denom - 1, 2 * p[1] / denom - 1, 2 * p[2] / denom - 1};
  double d = 0;
  switch (spec.kind) {
    case FieldKind::Sphere:
      d = std::abs(norm(u) - kSphereRadius);
      break;
    case FieldKind::Torus:
      d = std::abs(std::hypot(std::hypot(u[0], u[1]) - kTorusMajor, u[2]) - kTorusMinor);
      break;
    case FieldKind::CsgBox:
      d = csg_box_distance(u);
      break;
    case FieldKind::Gyroid:
      d = smooth_distance({gyroid_value, gyroid_grad, gyroid_hess, 0.0, kGyroidHessBound}, u);
      break;
    case FieldKind::MarschnerLobb:
      d = smooth_distance({ml_value, ml_grad, ml_hess, 0.5, kMlHessBound}, u);
      break;
  }
  return d * (denom / 2);
}

}  // namespace isotile
