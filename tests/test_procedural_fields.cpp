#include "core/volume/procedural_fields.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "core/errors.h"

namespace isotile {
namespace {

using std::numbers::pi;

constexpr std::array<FieldKind, 5> kAllKinds = {FieldKind::Sphere, FieldKind::Torus,
                                                FieldKind::Gyroid, FieldKind::CsgBox,
                                                FieldKind::MarschnerLobb};

double norm3(const Vec3d& a) {
  return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
}

// The header's normalised coordinate of grid index g.
double norm_coord(double g, std::int64_t n) {
  return 2.0 * g / static_cast<double>(n - 1) - 1.0;
}

Vec3d to_voxels(const Vec3d& u, std::int64_t n) {
  const double half = static_cast<double>(n - 1) / 2;
  return {(u[0] + 1) * half, (u[1] + 1) * half, (u[2] + 1) * half};
}

// Distance in normalised units, so tests can state expectations in the header's units.
double distance_norm(FieldKind kind, std::int64_t n, const Vec3d& u) {
  return distance_voxels({kind, n}, to_voxels(u, n)) / (static_cast<double>(n - 1) / 2);
}

std::string parse_error(std::string_view spec) {
  try {
    parse_field_spec(spec);
  } catch (const InputError& e) {
    return e.what();
  } catch (...) {
    return "<wrong exception type>";
  }
  return "<no exception>";
}

// ---- Parsing ----

TEST(FieldSpec, NonFieldInputIsNotASpec) {
  EXPECT_FALSE(parse_field_spec("volume.nrrd"));
  EXPECT_FALSE(parse_field_spec(""));
  EXPECT_FALSE(parse_field_spec("Field:sphere:8"));
  EXPECT_FALSE(parse_field_spec("fields:sphere:8"));
}

TEST(FieldSpec, ParsesEveryKnownName) {
  for (FieldKind k : kAllKinds) {
    const std::string spec = "field:" + std::string(field_name(k)) + ":64";
    const auto parsed = parse_field_spec(spec);
    ASSERT_TRUE(parsed) << spec;
    EXPECT_EQ(parsed->kind, k);
    EXPECT_EQ(parsed->n, 64);
  }
  const auto smallest = parse_field_spec("field:torus:2");
  ASSERT_TRUE(smallest);
  EXPECT_EQ(smallest->n, 2);
  const auto large = parse_field_spec("field:gyroid:1000000");
  ASSERT_TRUE(large);
  EXPECT_EQ(large->n, 1000000);
}

TEST(FieldSpec, NamesAndDefaultIsovalues) {
  const std::vector<std::string_view> expected = {"sphere", "torus", "gyroid", "csg-box",
                                                  "marschner-lobb"};
  EXPECT_EQ(field_names(), expected);
  for (FieldKind k : kAllKinds)
    EXPECT_EQ(field_default_iso(k), k == FieldKind::MarschnerLobb ? 0.5 : 0.0);
}

TEST(FieldSpec, UnknownNameListsKnownNames) {
  const std::string msg = parse_error("field:cube:32");
  EXPECT_NE(msg.find("'cube'"), std::string::npos) << msg;
  for (std::string_view name : field_names()) EXPECT_NE(msg.find(name), std::string::npos) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos);
}

TEST(FieldSpec, RejectsBadSizes) {
  for (const char* spec :
       {"field:sphere:1", "field:sphere:0", "field:sphere:-3", "field:sphere:abc",
        "field:sphere:10x", "field:sphere:", "field:sphere: 8", "field:sphere:+8",
        "field:sphere:8.0", "field:sphere:10000000", "field:sphere:3000000",
        "field:sphere:99999999999999999999999", "field:sphere", "field:"}) {
    EXPECT_THROW(parse_field_spec(spec), InputError) << spec;
    EXPECT_EQ(parse_error(spec).find('\n'), std::string::npos) << spec;
  }
  EXPECT_NE(parse_error("field:sphere:1").find("at least 2"), std::string::npos);
  EXPECT_NE(parse_error("field:sphere:10000000").find("too large"), std::string::npos);
}

// ---- Field values and sampling ----

TEST(FieldValue, KnownValues) {
  EXPECT_DOUBLE_EQ(field_value(FieldKind::Sphere, {0, 0, 0}), 0.75);
  EXPECT_NEAR(field_value(FieldKind::Sphere, {0.75, 0, 0}), 0, 1e-15);
  EXPECT_NEAR(field_value(FieldKind::Torus, {0.5, 0, 0}), 0.2, 1e-15);
  EXPECT_NEAR(field_value(FieldKind::Torus, {0, 0.7, 0}), 0, 1e-15);
  EXPECT_NEAR(field_value(FieldKind::Torus, {0, 0, 0}), -0.3, 1e-15);
  EXPECT_NEAR(field_value(FieldKind::Gyroid, {0.125, 0.125, 0.125}), 1.5, 1e-14);
  EXPECT_NEAR(field_value(FieldKind::Gyroid, {0, 0, 0}), 0, 1e-15);
  // Box-dominated interior and ball-dominated cavity.
  EXPECT_NEAR(field_value(FieldKind::CsgBox, {-0.5, -0.5, -0.5}), 0.1, 1e-15);
  EXPECT_NEAR(field_value(FieldKind::CsgBox, {0.6, 0.6, 0.6}), -0.5, 1e-15);
  EXPECT_NEAR(field_value(FieldKind::CsgBox, {-1, 0, 0}), -0.4, 1e-15);
  // Marschner-Lobb at the origin: (1 - 0 + 0.25 * (1 + cos(12 pi))) / 2.5.
  EXPECT_NEAR(field_value(FieldKind::MarschnerLobb, {0, 0, 0}), 0.6, 1e-15);
  const double r = 0.3, z = 0.2;
  const double ml =
      (1 - std::sin(pi * z / 2) + 0.25 * (1 + std::cos(2 * pi * 6 * std::cos(pi * r / 2)))) / 2.5;
  EXPECT_NEAR(field_value(FieldKind::MarschnerLobb, {0.6 * r, 0.8 * r, z}), ml, 1e-15);
}

TEST(FieldValue, InsideIsAtOrAboveIso) {
  auto above = [](FieldKind k, const Vec3d& u) { return field_value(k, u) > field_default_iso(k); };
  EXPECT_TRUE(above(FieldKind::Sphere, {0, 0, 0}));
  EXPECT_TRUE(above(FieldKind::Torus, {0.5, 0, 0}));  // tube centre
  EXPECT_TRUE(above(FieldKind::Torus, {0, -0.5, 0}));
  EXPECT_FALSE(above(FieldKind::Torus, {0, 0, 0}));  // the hole
  EXPECT_TRUE(above(FieldKind::CsgBox, {0, 0, 0}));
  EXPECT_TRUE(above(FieldKind::CsgBox, {-0.3, -0.3, -0.3}));
  EXPECT_FALSE(above(FieldKind::CsgBox, {0.5, 0.5, 0.5}));  // carved out by the ball
  EXPECT_TRUE(above(FieldKind::MarschnerLobb, {0, 0, -0.5}));
  EXPECT_FALSE(above(FieldKind::MarschnerLobb, {0, 0, 0.5}));
  for (FieldKind k : {FieldKind::Sphere, FieldKind::Torus, FieldKind::CsgBox})
    for (double x : {-1.0, 1.0})
      for (double y : {-1.0, 1.0})
        for (double z : {-1.0, 1.0}) EXPECT_FALSE(above(k, {x, y, z})) << field_name(k);
}

TEST(FieldVolume, SamplesMatchFieldValue) {
  for (FieldKind k : kAllKinds) {
    for (std::int64_t n : {2, 9, 16}) {
      const Volume vol = make_field_volume({k, n});
      EXPECT_EQ(vol.type(), ScalarType::Float32);
      EXPECT_EQ(vol.dims(), (Index3{n, n, n}));
      EXPECT_EQ(vol.spacing(), (Vec3d{1, 1, 1}));
      EXPECT_EQ(vol.origin(), (Vec3d{0, 0, 0}));
      const VolumeView view = vol.view();
      const std::vector<Index3> chosen = {{0, 0, 0},     {n - 1, n - 1, n - 1},
                                          {n - 1, 0, 0}, {0, n - 1, 1},
                                          {1, 0, n - 1}, {n / 2, n / 3, n - 2}};
      for (const Index3& g : chosen) {
        const Vec3d u = {norm_coord(double(g[0]), n), norm_coord(double(g[1]), n),
                         norm_coord(double(g[2]), n)};
        EXPECT_EQ(view.value(g[0], g[1], g[2]), static_cast<float>(field_value(k, u)))
            << field_name(k) << " n=" << n << " at " << g[0] << "," << g[1] << "," << g[2];
      }
    }
  }
}

TEST(FieldVolume, RejectsTooFewSamples) {
  EXPECT_THROW(make_field_volume({FieldKind::Sphere, 1}), InputError);
  EXPECT_THROW(make_field_volume({FieldKind::Sphere, 0}), InputError);
}

TEST(FieldVolume, CentreAndCornerSigns) {
  for (FieldKind k : {FieldKind::Sphere, FieldKind::CsgBox}) {
    const Volume vol = make_field_volume({k, 33});
    EXPECT_GT(vol.view().value(16, 16, 16), 0) << field_name(k);
    EXPECT_LT(vol.view().value(0, 0, 0), 0) << field_name(k);
    EXPECT_LT(vol.view().value(32, 32, 32), 0) << field_name(k);
  }
  // Index 24 of 33 is u = 0.5: the torus tube centre.
  const Volume torus = make_field_volume({FieldKind::Torus, 33});
  EXPECT_NEAR(torus.view().value(24, 16, 16), 0.2, 1e-7);
  EXPECT_LT(torus.view().value(16, 16, 16), 0);
}

TEST(FieldVolume, Deterministic) {
  const Volume a = make_field_volume({FieldKind::Gyroid, 41});
  const Volume b = make_field_volume({FieldKind::Gyroid, 41});
  ASSERT_EQ(a.byte_size(), b.byte_size());
  EXPECT_EQ(std::memcmp(a.bytes(), b.bytes(), a.byte_size()), 0);
}

// ---- Exact distances ----

Vec3d random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> g;
  for (;;) {
    const Vec3d v = {g(rng), g(rng), g(rng)};
    const double l = norm3(v);
    if (l > 1e-6) return {v[0] / l, v[1] / l, v[2] / l};
  }
}

TEST(FieldDistance, SphereExact) {
  const std::int64_t n = 65;  // 32 voxels per normalised unit
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> off(-0.5, 0.5);
  for (int i = 0; i < 200; ++i) {
    const Vec3d d = random_unit(rng);
    const double t = off(rng);
    const double r = 0.75 + t;
    const Vec3d p = to_voxels({r * d[0], r * d[1], r * d[2]}, n);
    EXPECT_NEAR(distance_voxels({FieldKind::Sphere, n}, p), std::abs(t) * 32, 1e-12);
  }
  EXPECT_NEAR(distance_voxels({FieldKind::Sphere, n}, {32, 32, 32}), 24, 1e-12);
  EXPECT_NEAR(distance_voxels({FieldKind::Sphere, n}, {32 + 24, 32, 32}), 0, 1e-12);
}

TEST(FieldDistance, TorusExact) {
  const std::int64_t n = 65;
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> angle(0, 2 * pi), off(-0.2, 0.25);
  for (int i = 0; i < 200; ++i) {
    const double theta = angle(rng), phi = angle(rng), t = off(rng);
    const double rho = 0.5 + (0.2 + t) * std::cos(phi);
    const Vec3d u = {rho * std::cos(theta), rho * std::sin(theta), (0.2 + t) * std::sin(phi)};
    EXPECT_NEAR(distance_voxels({FieldKind::Torus, n}, to_voxels(u, n)), std::abs(t) * 32, 1e-12);
  }
  EXPECT_NEAR(distance_voxels({FieldKind::Torus, n}, {32, 32, 32}), 0.3 * 32, 1e-12);
}

// Surface points of the csg-box, from its two kinds of patch: box faces outside the ball, and the
// ball's octant towards -(1,1,1), which is the part inside the box.
std::vector<Vec3d> csg_box_surface_samples(int res) {
  const double a = 0.6, rad = 0.5;
  std::vector<Vec3d> pts;
  for (int axis = 0; axis < 3; ++axis)
    for (double side : {-a, a})
      for (int i = 0; i <= res; ++i)
        for (int j = 0; j <= res; ++j) {
          Vec3d p;
          p[axis] = side;
          p[(axis + 1) % 3] = -a + 2 * a * i / res;
          p[(axis + 2) % 3] = -a + 2 * a * j / res;
          if (norm3({p[0] - a, p[1] - a, p[2] - a}) >= rad) pts.push_back(p);
        }
  for (int i = 0; i <= res; ++i)
    for (int j = 0; j <= res; ++j) {
      const double th = (pi / 2) * i / res, ph = (pi / 2) * j / res;
      pts.push_back({a - rad * std::sin(th) * std::cos(ph), a - rad * std::sin(th) * std::sin(ph),
                     a - rad * std::cos(th)});
    }
  return pts;
}

TEST(FieldDistance, CsgBoxZeroOnEverySurfacePart) {
  const std::int64_t n = 65;
  const double a = 0.6, rad = 0.5;
  std::vector<Vec3d> on = {
      {a, 0, 0},       {-a, 0.2, -0.3}, {0.1, -a, 0.5},  {0.3, 0.4, -a}, {-0.5, 0.55, a},  // faces
      {a, a, -0.3},    {-a, a, 0},      {a, -a, a},      {-a, -a, 0.59}, {0.2, a, -a},     // edges
      {-a, -a, -a},    {a, -a, -a},     {-a, a, a},       // corners
      {a, a, a - rad}, {a - rad, a, a}, {a, a - rad, a},  // crease meets edge
  };
  for (double phi : {0.1, 0.5, 0.785398, 1.2, 1.5}) {
    const double c = rad * std::cos(phi), s = rad * std::sin(phi);
    on.push_back({a, a - c, a - s});  // the circular crease on each of the three cut faces
    on.push_back({a - c, a, a - s});
    on.push_back({a - c, a - s, a});
  }
  for (double th : {0.2, 0.7, 1.1})
    for (double ph : {0.1, 0.8, 1.4})
      on.push_back({a - rad * std::sin(th) * std::cos(ph), a - rad * std::sin(th) * std::sin(ph),
                    a - rad * std::cos(th)});
  for (const Vec3d& u : on) {
    EXPECT_NEAR(distance_norm(FieldKind::CsgBox, n, u), 0, 1e-12)
        << u[0] << "," << u[1] << "," << u[2];
    EXPECT_NEAR(field_value(FieldKind::CsgBox, u), 0, 1e-12) << u[0] << "," << u[1] << "," << u[2];
  }
}

TEST(FieldDistance, CsgBoxExactWhereTheCsgBoundIsNot) {
  // Outside the box in the carved corner, the nearest surface points are where the crease meets
  // the box edges, e.g. (0.6, 0.6, 0.1); the CSG value only bounds that distance.
  const std::int64_t n = 65;
  const Vec3d p = {0.7, 0.7, 0.7};
  EXPECT_NEAR(distance_norm(FieldKind::CsgBox, n, p), std::sqrt(0.38), 1e-12);
  EXPECT_LT(-field_value(FieldKind::CsgBox, p), std::sqrt(0.38) - 0.2);
  // Inside the box far from the ball, the nearest face decides.
  EXPECT_NEAR(distance_norm(FieldKind::CsgBox, n, {-0.5, -0.2, 0.1}), 0.1, 1e-12);
  // The ball centre: every point of the sphere patch is at the radius.
  EXPECT_NEAR(distance_norm(FieldKind::CsgBox, n, {0.6, 0.6, 0.6}), 0.5, 1e-12);
}

TEST(FieldDistance, CsgBoxMatchesBruteForce) {
  const int res = 200;
  const std::vector<Vec3d> samples = csg_box_surface_samples(res);
  // Every surface point is within this of a sample: half a face cell's diagonal, or, next to the
  // circular crease where a cell's corners may be cut away, a full cell diagonal plus half the
  // crease's sample spacing.
  const double cell = 1.2 / res;
  const double bound = cell * std::sqrt(2.0) + 0.5 * (pi / 2) / res + 1e-12;

  const std::int64_t n = 97;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> near(-0.15, 0.15), anywhere(-1, 1);
  std::uniform_int_distribution<std::size_t> pick(0, samples.size() - 1);
  for (int q = 0; q < 200; ++q) {
    Vec3d p;
    if (q < 160) {
      const Vec3d& s = samples[pick(rng)];
      p = {s[0] + near(rng), s[1] + near(rng), s[2] + near(rng)};
    } else {
      p = {anywhere(rng), anywhere(rng), anywhere(rng)};
    }
    double brute = std::numeric_limits<double>::infinity();
    for (const Vec3d& s : samples)
      brute = std::min(brute, norm3({p[0] - s[0], p[1] - s[1], p[2] - s[2]}));
    const double exact = distance_norm(FieldKind::CsgBox, n, p);
    EXPECT_LE(exact, brute + 1e-9) << p[0] << "," << p[1] << "," << p[2];
    EXPECT_LE(brute, exact + bound) << p[0] << "," << p[1] << "," << p[2];
  }
}

// ---- Newton-projected distances (gyroid, Marschner-Lobb) ----

double ref_value(FieldKind k, const Vec3d& u) {
  if (k == FieldKind::Gyroid) {
    const double w = 2 * pi;
    return std::sin(w * u[0]) * std::cos(w * u[1]) + std::sin(w * u[1]) * std::cos(w * u[2]) +
           std::sin(w * u[2]) * std::cos(w * u[0]);
  }
  const double r = std::hypot(u[0], u[1]);
  return (1 - std::sin(pi * u[2] / 2) + 0.25 * (1 + std::cos(12 * pi * std::cos(pi * r / 2)))) /
             2.5 -
         0.5;
}

Vec3d ref_normal(FieldKind k, const Vec3d& u) {
  const double h = 1e-6;
  Vec3d g;
  for (int a = 0; a < 3; ++a) {
    Vec3d lo = u, hi = u;
    lo[a] -= h;
    hi[a] += h;
    g[a] = (ref_value(k, hi) - ref_value(k, lo)) / (2 * h);
  }
  const double l = norm3(g);
  return {g[0] / l, g[1] / l, g[2] / l};
}

// A surface point above (x, y): the first sign change along z from z0, bisected to rounding.
std::optional<Vec3d> surface_point(FieldKind k, double x, double y, double z0) {
  const double step = 0.01;
  double lo = z0, flo = ref_value(k, {x, y, lo});
  for (double z = z0 + step; z < z0 + 1; z += step) {
    const double f = ref_value(k, {x, y, z});
    if ((f > 0) != (flo > 0)) {
      double hi = z;
      for (int i = 0; i < 200; ++i) {
        const double mid = 0.5 * (lo + hi);
        if ((ref_value(k, {x, y, mid}) > 0) == (flo > 0))
          lo = mid;
        else
          hi = mid;
      }
      return Vec3d{x, y, lo};
    }
    lo = z;
    flo = f;
  }
  return std::nullopt;
}

// Surface points s (found independently of the library) and p = s + t n along the normal: the
// distance to the surface is |t| as long as |t| is below the local radius of curvature.
void check_newton_distance(FieldKind k, double z0, std::initializer_list<double> offsets_vox,
                           double tol_vox) {
  const std::int64_t n = 64;
  const double half = (n - 1) / 2.0;
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> xy(-0.95, 0.95);
  int checked = 0;
  for (int i = 0; i < 100; ++i) {
    const auto s = surface_point(k, xy(rng), xy(rng), z0);
    if (!s) continue;
    ++checked;
    const Vec3d nrm = ref_normal(k, *s);
    EXPECT_NEAR(distance_voxels({k, n}, to_voxels(*s, n)), 0, 1e-9);
    for (double t_vox : offsets_vox) {
      const double t = t_vox / half;
      const Vec3d p = {(*s)[0] + t * nrm[0], (*s)[1] + t * nrm[1], (*s)[2] + t * nrm[2]};
      EXPECT_NEAR(distance_voxels({k, n}, to_voxels(p, n)), std::abs(t_vox), tol_vox)
          << field_name(k) << " t=" << t_vox << " at " << (*s)[0] << "," << (*s)[1] << ","
          << (*s)[2];
    }
  }
  EXPECT_GT(checked, 50);
}

TEST(FieldDistance, GyroidNewtonNearSurface) {
  check_newton_distance(FieldKind::Gyroid, -0.9, {0.01, -0.01, 0.001}, 1e-4);
}

TEST(FieldDistance, MarschnerLobbNewtonNearSurface) {
  check_newton_distance(FieldKind::MarschnerLobb, -0.5, {0.01, -0.01, 0.001}, 1e-4);
}

// A plain Newton foot is off by about t^3 k^2 / 2 (k the curvature); the foot-point refinement
// makes the distance exact to rounding for these offsets.
TEST(FieldDistance, GyroidFootPointIsPerpendicular) {
  check_newton_distance(FieldKind::Gyroid, -0.9, {0.3, -0.3, 0.6}, 1e-8);
}

// The Marschner-Lobb surface is the graph z = h(x, y) = (2/pi) asin(alpha rho_r(r)); its rim
// ripples are so tight that the nearest point may be on a neighbouring ripple. The oracle samples
// the graph on a grid around p and zooms in on the best sample.
double ml_graph_distance(const Vec3d& p, double radius) {
  auto h = [](double x, double y) {
    const double r = std::hypot(x, y);
    return (2 / pi) * std::asin(0.25 * std::cos(12 * pi * std::cos(pi * r / 2)));
  };
  auto dist = [&](double x, double y) { return norm3({x - p[0], y - p[1], h(x, y) - p[2]}); };
  double cx = p[0], cy = p[1], window = radius;
  double best = std::numeric_limits<double>::infinity();
  int cells = std::max(20, static_cast<int>(std::ceil(2 * radius / 2e-4)));
  for (int level = 0; level < 12; ++level) {
    const double step = 2 * window / cells;
    double bx = cx, by = cy;
    for (int i = 0; i <= cells; ++i)
      for (int j = 0; j <= cells; ++j) {
        const double x = cx - window + i * step, y = cy - window + j * step;
        const double d = dist(x, y);
        if (d < best) {
          best = d;
          bx = x;
          by = y;
        }
      }
    cx = bx;
    cy = by;
    window = 2 * step;
    cells = 20;
  }
  return best;
}

TEST(FieldDistance, MarschnerLobbNearestRipple) {
  const std::int64_t n = 32;
  const double half = (n - 1) / 2.0;
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<double> xy(-0.95, 0.95), off(0, 0.5 / half);
  for (int i = 0; i < 40; ++i) {
    const auto s = surface_point(FieldKind::MarschnerLobb, xy(rng), xy(rng), -0.5);
    ASSERT_TRUE(s);
    const Vec3d dir = random_unit(rng);
    const double t = off(rng);
    const Vec3d p = {(*s)[0] + t * dir[0], (*s)[1] + t * dir[1], (*s)[2] + t * dir[2]};
    const double d = distance_norm(FieldKind::MarschnerLobb, n, p);
    const double oracle = ml_graph_distance(p, t + 1e-6);
    EXPECT_LE(d, oracle + 1e-9) << p[0] << "," << p[1] << "," << p[2];
    EXPECT_LE(oracle, d + 1e-6) << p[0] << "," << p[1] << "," << p[2];
  }
  // Points where the Newton foot from p alone lands on the wrong ripple.
  for (const Vec3d& p :
       {Vec3d{0.33882726982482148, 0.15467547719909966, 0.040386476461201221},
        Vec3d{-0.45770740234818535, -0.045796307814834722, -0.13331230747264108}}) {
    const double d = distance_norm(FieldKind::MarschnerLobb, n, p);
    const double oracle = ml_graph_distance(p, d + 1e-6);
    EXPECT_LE(d, oracle + 1e-9) << p[0] << "," << p[1] << "," << p[2];
    EXPECT_LE(oracle, d + 1e-6) << p[0] << "," << p[1] << "," << p[2];
  }
}

TEST(FieldDistance, GyroidAtACriticalPoint) {
  // The gyroid's maximum 1.5 at (1/8, 1/8, 1/8) has a zero gradient, so Newton cannot start there.
  const std::int64_t n = 65;
  const Vec3d c = {0.125, 0.125, 0.125};
  const double d = distance_norm(FieldKind::Gyroid, n, c);
  ASSERT_TRUE(std::isfinite(d));
  // No surface inside the ball of radius d (sampled) ...
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int i = 0; i < 5000; ++i) {
    const Vec3d dir = random_unit(rng);
    const double r = 0.999 * d * std::cbrt(unit(rng));
    EXPECT_GT(
        ref_value(FieldKind::Gyroid, {c[0] + r * dir[0], c[1] + r * dir[1], c[2] + r * dir[2]}), 0);
  }
  // ... and no ray reaches the surface sooner.
  double upper = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 2000; ++i) {
    const Vec3d dir = random_unit(rng);
    auto at = [&](double t) {
      return ref_value(FieldKind::Gyroid,
                       {c[0] + t * dir[0], c[1] + t * dir[1], c[2] + t * dir[2]});
    };
    for (double t = 0.002; t < 0.6; t += 0.002) {
      if (at(t) > 0) continue;
      double lo = t - 0.002, hi = t;
      for (int b = 0; b < 100; ++b) (at(0.5 * (lo + hi)) > 0 ? lo : hi) = 0.5 * (lo + hi);
      upper = std::min(upper, hi);
      break;
    }
  }
  EXPECT_LE(d, upper + 1e-9);
}

}  // namespace
}  // namespace isotile

namespace isotile {
namespace {

// Bricks of a field must be the same bits as the whole volume (the tiler relies on it), and the
// separable fast paths must agree with field_value exactly.
TEST(ProceduralFields, BoxesAreBitIdenticalToTheWholeVolumeAndToFieldValue) {
  for (std::string_view name : field_names()) {
    const FieldSpec spec = *parse_field_spec("field:" + std::string(name) + ":23");
    const Volume whole = make_field_volume(spec);
    const Box3 box{{3, 0, 7}, {20, 11, 23}};
    std::vector<float> part(static_cast<std::size_t>(17 * 11 * 16));
    fill_field_box(spec, box, part.data());
    std::size_t n = 0;
    for (std::int64_t k = box.lo[2]; k < box.hi[2]; ++k)
      for (std::int64_t j = box.lo[1]; j < box.hi[1]; ++j)
        for (std::int64_t i = box.lo[0]; i < box.hi[0]; ++i, ++n) {
          const float w = whole.data<float>()[(k * 23 + j) * 23 + i];
          ASSERT_EQ(part[n], w) << name << " at " << i << "," << j << "," << k;
          const auto c = [](std::int64_t g) { return 2.0 * static_cast<double>(g) / 22.0 - 1.0; };
          ASSERT_EQ(w, static_cast<float>(field_value(spec.kind, {c(i), c(j), c(k)}))) << name;
        }
  }
}

}  // namespace
}  // namespace isotile
