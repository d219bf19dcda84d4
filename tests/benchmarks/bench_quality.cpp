// Accuracy of the extractors against the exact surfaces of the procedural fields: regenerates
// the accuracy table of docs/quality.md.
//
//   bench_quality [--field NAME] [N ...]   (default: every smooth field and csg-box; 32 64 128)
//   bench_quality --speed [--threads T]   (DC's cost against MC's on bonsai and engine)
//
// For each field (sphere, torus, gyroid, csg-box), grid size N and method, it prints one
// markdown row: the vertex distance to the exact surface (mean, max; in voxels), a sampled
// symmetric surface distance (mean and max over both directions: points sampled on the mesh
// triangles measured against the exact surface, and points sampled on the exact surface measured
// against the mesh), the radius ratio (mean, min) and the extraction time (one run, indicative).
// Samples use fixed seeds, so the table is the same on every run.
//
// --speed times MC and each DC variant side by side in one run, on the same in-memory samples and
// thread count (default 2): the median of 9 extractions each, and its ratio to MC's median.
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/parallel_for.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "core/extract/dual_contouring.h"
#include "core/extract/marching_cubes.h"
#include "core/mesh/mesh_quality.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"

#include <tbb/global_control.h>
#include <algorithm>
#include <filesystem>

using namespace isotile;

namespace {

using K = CGAL::Simple_cartesian<double>;
using Triangles = std::vector<K::Triangle_3>;
using Tree = CGAL::AABB_tree<
    CGAL::AABB_traits<K, CGAL::AABB_triangle_primitive<K, Triangles::const_iterator>>>;

struct Method {
  std::string name;
  std::function<Mesh(const VolumeView&, double iso)> run;
};

std::vector<Method> methods() {
  auto dc = [](DcSolver solver, DcHermite hermite, int steps) {
    return [=](const VolumeView& v, double iso) {
      DualContouringOptions o;
      o.iso = iso;
      o.solver = solver;
      o.hermite = hermite;
      if (steps > 0) {
        o.particle_steps = steps;
        o.particle_tolerance = 1e-6;
      }
      return dual_contouring(v, o);
    };
  };
  const auto C = DcHermite::Central, E = DcHermite::Eno;
  return {
      {"MC", [](const VolumeView& v, double iso) { return marching_cubes(v, {.iso = iso}); }},
      {"DC mass point", dc(DcSolver::MassPoint, C, 0)},
      {"DC particle 10", dc(DcSolver::Particle, C, 10)},
      {"DC QEF", dc(DcSolver::Qef, C, 0)},
      {"DC mass point, ENO", dc(DcSolver::MassPoint, E, 0)},
      {"DC particle 10, ENO", dc(DcSolver::Particle, E, 10)},
      {"DC particle 100, ENO", dc(DcSolver::Particle, E, 100)},
      {"DC QEF, ENO", dc(DcSolver::Qef, E, 0)},
  };
}

// Normalised field coordinates u of voxel point p, and back.
Vec3d to_u(const Vec3d& p, std::int64_t n) {
  Vec3d u;
  for (int a = 0; a < 3; ++a) u[a] = 2 * p[a] / static_cast<double>(n - 1) - 1;
  return u;
}
Vec3d to_p(const Vec3d& u, std::int64_t n) {
  Vec3d p;
  for (int a = 0; a < 3; ++a) p[a] = (u[a] + 1) * 0.5 * static_cast<double>(n - 1);
  return p;
}

// About `count` points on the exact surface, spread by area: uniform points in a thin shell around
// the surface (first-order distance under a quarter voxel, at least a voxel inside the domain so
// open meshes are not penalised at the border), projected by Newton steps and kept when the exact
// distance confirms they lie on it.
std::vector<Vec3d> surface_samples(const FieldSpec& spec, std::size_t count) {
  const double iso = field_default_iso(spec.kind);
  const double h = 1e-7, to_voxels = 0.5 * static_cast<double>(spec.n - 1);
  auto grad = [&](const Vec3d& u) {
    Vec3d g;
    for (int a = 0; a < 3; ++a) {
      Vec3d hi = u, lo = u;
      hi[a] += h;
      lo[a] -= h;
      g[a] = (field_value(spec.kind, hi) - field_value(spec.kind, lo)) / (2 * h);
    }
    return g;
  };
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> coord(1.0, static_cast<double>(spec.n - 2));
  std::vector<Vec3d> out;
  for (std::size_t tries = 0; out.size() < count && tries < 200 * count + 10000000; ++tries) {
    Vec3d p{coord(rng), coord(rng), coord(rng)};
    Vec3d u = to_u(p, spec.n);
    Vec3d g = grad(u);
    const double g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
    if (!(g2 > 0)) continue;
    const double f = field_value(spec.kind, u) - iso;
    if (std::fabs(f) / std::sqrt(g2) * to_voxels > 0.25) continue;
    for (int it = 0; it < 30; ++it) {
      g = grad(u);
      const double gg = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
      const double r = field_value(spec.kind, u) - iso;
      if (!(gg > 0)) break;
      for (int a = 0; a < 3; ++a) u[a] -= r * g[a] / gg;
    }
    p = to_p(u, spec.n);
    bool inside = true;
    for (int a = 0; a < 3; ++a) inside = inside && p[a] >= 1 && p[a] <= spec.n - 2;
    if (inside && distance_voxels(spec, p) < 1e-5) out.push_back(p);
  }
  return out;
}

struct Row {
  double v_mean = 0, v_max = 0, s_mean = 0, s_max = 0;
};

// Sums over fixed chunks in chunk order: the same result for any thread count.
template <class F>
std::pair<double, double> mean_max(std::size_t n, F&& distance) {
  constexpr std::size_t kChunk = 1024;
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  std::vector<double> sum(chunks), max(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    double s = 0, m = 0;
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const double d = distance(i);
      s += d;
      m = std::max(m, d);
    }
    sum[c] = s;
    max[c] = m;
  });
  double s = 0, m = 0;
  for (std::size_t c = 0; c < chunks; ++c) {
    s += sum[c];
    m = std::max(m, max[c]);
  }
  return {n ? s / static_cast<double>(n) : 0.0, m};
}

Row measure(const FieldSpec& spec, const Mesh& mesh, const std::vector<Vec3d>& on_surface) {
  Row row;
  const auto& pos = mesh.positions;
  std::tie(row.v_mean, row.v_max) = mean_max(pos.size(), [&](std::size_t i) {
    return distance_voxels(spec, {pos[i][0], pos[i][1], pos[i][2]});
  });
  // Mesh -> surface: the centroid and two more fixed barycentric points of every triangle (of
  // every k-th triangle past 20,000, to bound the cost of the gyroid's foot-point searches).
  std::vector<Tri> tris = mesh.triangles;
  for (const Quad& q : mesh.quads) {
    tris.push_back({q[0], q[1], q[2]});
    tris.push_back({q[0], q[2], q[3]});
  }
  static const double bary[3][3] = {{1 / 3.0, 1 / 3.0, 1 / 3.0}, {0.6, 0.2, 0.2}, {0.2, 0.2, 0.6}};
  const std::size_t stride = tris.size() / 20000 + 1;
  const auto [m_mean, m_max] =
      mean_max(3 * ((tris.size() + stride - 1) / stride), [&](std::size_t i) {
        const Tri& t = tris[(i / 3) * stride];
        const double* w = bary[i % 3];
        Vec3d p{0, 0, 0};
        for (int c = 0; c < 3; ++c)
          for (int a = 0; a < 3; ++a) p[a] += w[c] * pos[t[c]][a];
        return distance_voxels(spec, p);
      });
  // Surface -> mesh.
  Triangles cgal;
  cgal.reserve(tris.size());
  auto pt = [&](std::uint32_t v) { return K::Point_3(pos[v][0], pos[v][1], pos[v][2]); };
  for (const Tri& t : tris) cgal.emplace_back(pt(t[0]), pt(t[1]), pt(t[2]));
  Tree tree(cgal.begin(), cgal.end());
  tree.accelerate_distance_queries();
  const auto [s_mean, s_max] = mean_max(on_surface.size(), [&](std::size_t i) {
    const Vec3d& p = on_surface[i];
    return std::sqrt(tree.squared_distance(K::Point_3(p[0], p[1], p[2])));
  });
  row.s_mean = 0.5 * (m_mean + s_mean);
  row.s_max = std::max(m_max, s_max);
  return row;
}

}  // namespace

int speed(int threads) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  std::printf("| volume | method | median ms (%d threads) | x MC |\n| --- | --- | --- | --- |\n",
              threads);
  for (const char* file : {"bonsai_256x256x256_uint8.raw.gz", "engine_256x256x128_uint8.raw.gz"}) {
    const std::filesystem::path path = std::filesystem::path(ISOTILE_SHARED_DATA) / file;
    if (!std::filesystem::exists(path)) {
      std::fprintf(stderr, "skipping %s: not found\n", path.c_str());
      continue;
    }
    const Volume vol = read_volume(path.string());
    double mc_ms = 0;
    for (const Method& m : methods()) {
      std::vector<double> ms;
      for (int rep = 0; rep < 9; ++rep) {
        const auto t0 = std::chrono::steady_clock::now();
        const Mesh mesh = m.run(vol.view(), 49.5);
        ms.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count());
      }
      std::sort(ms.begin(), ms.end());
      if (m.name == "MC") mc_ms = ms[4];
      std::printf("| %s | %s | %.1f | %.2f |\n", path.stem().stem().c_str(), m.name.c_str(), ms[4],
                  ms[4] / mc_ms);
      std::fflush(stdout);
    }
  }
  return 0;
}

int usage(const char* problem) {
  std::fprintf(stderr,
               "bench_quality: %s\n"
               "usage: bench_quality [--field NAME] [N ...]   (default sizes: 32 64 128)\n"
               "       bench_quality --speed [--threads T]\n",
               problem);
  return 2;
}

// A whole-string integer >= lo, or nothing.
bool parse_int(const char* s, long long lo, long long& out) {
  char* end = nullptr;
  errno = 0;
  out = std::strtoll(s, &end, 10);
  return errno == 0 && end != s && *end == '\0' && out >= lo;
}

int main(int argc, char** argv) {
  std::vector<std::int64_t> sizes;
  std::vector<FieldKind> kinds;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    long long v = 0;
    if (arg == "--help" || arg == "-h") {
      std::printf(
          "usage: bench_quality [--field NAME] [N ...]   (default sizes: 32 64 128)\n"
          "       bench_quality --speed [--threads T]\n");
      return 0;
    } else if (arg == "--speed") {
      if (i + 1 == argc) return speed(2);
      if (i + 3 == argc && std::string(argv[i + 1]) == "--threads" && parse_int(argv[i + 2], 1, v))
        return speed(static_cast<int>(v));
      return usage("--speed takes only --threads T (T >= 1)");
    } else if (arg == "--field") {
      if (i + 1 == argc) return usage("--field needs a name");
      try {
        kinds.push_back(parse_field_spec("field:" + std::string(argv[++i]) + ":2")->kind);
      } catch (const std::exception& e) {
        return usage(e.what());
      }
    } else if (parse_int(argv[i], 2, v)) {
      sizes.push_back(v);
    } else {
      return usage(("not a grid size (an integer >= 2) or option: '" + arg + "'").c_str());
    }
  }
  if (sizes.empty()) sizes = {32, 64, 128};
  if (kinds.empty())
    kinds = {FieldKind::Sphere, FieldKind::Torus, FieldKind::Gyroid, FieldKind::CsgBox};
  std::printf(
      "| field | N | method | vertex mean | vertex max | surface mean | surface max | q mean | "
      "q min | ms |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  for (FieldKind kind : kinds)
    for (std::int64_t n : sizes) {
      const FieldSpec spec{kind, n};
      const Volume vol = make_field_volume(spec);
      const std::vector<Vec3d> on_surface = surface_samples(spec, 20000);
      for (const Method& m : methods()) {
        const auto t0 = std::chrono::steady_clock::now();
        const Mesh mesh = m.run(vol.view(), field_default_iso(kind));
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count();
        const Row r = measure(spec, mesh, on_surface);
        const QualityStats q = triangle_quality(mesh);
        std::printf("| %s | %lld | %s | %.4f | %.4f | %.4f | %.4f | %.3f | %.3g | %.1f |\n",
                    std::string(field_name(kind)).c_str(), static_cast<long long>(n),
                    m.name.c_str(), r.v_mean, r.v_max, r.s_mean, r.s_max, q.mean, q.min, ms);
        std::fflush(stdout);
      }
    }
  return 0;
}
