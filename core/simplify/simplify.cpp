#include "core/simplify/simplify.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/mesh/mesh_quality.h"
#include "core/simplify/simplify_region.h"

namespace isotile {

namespace {

// Faces per region. Large enough that seams are a small share of a region, small enough that a
// 256^3 scan's surface gives a few regions per thread.
constexpr std::uint64_t kRegionFaces = std::uint64_t{1} << 16;

// Faces the first pass expects to stay around each vertex it locks on a seam. Measured on
// bonsai's Macet mesh at a tenth (docs/simplify.md): 0 gives a mean distance of 0.27 voxel, 2
// gives 0.14, 4 gives 0.13 and the best shapes, 10 and 20 worse again.
constexpr double kSeamFaces = 4;

// The mesh between passes: vertices keep their quadrics and locks from pass to pass.
struct WorkMesh {
  std::vector<Vec3d> positions;
  std::vector<Quadric> quadrics;
  std::vector<std::uint8_t> locked;  // split copies (the boundary is found in each region)
  std::vector<std::int32_t> group;   // split copies: their input vertex; -1 elsewhere; or empty
  std::vector<Tri> triangles;
  std::vector<std::uint32_t> origin;  // the input vertex each vertex is (copies: their original)
  std::vector<Vec3d> points;          // with an error bound: see Region::points
  std::vector<std::uint32_t> point_face;
};

Vec3d sub(const Vec3d& a, const Vec3d& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}

// Vertex -> faces in ascending face order (count, scan, fill).
struct VertexFaces {
  std::vector<std::uint64_t> start;  // per vertex, plus one
  std::vector<std::uint32_t> faces;
  VertexFaces(std::size_t vertices, const std::vector<Tri>& tris) : start(vertices + 1, 0) {
    for (const Tri& t : tris)
      for (std::uint32_t v : t) ++start[v + 1];
    std::partial_sum(start.begin(), start.end(), start.begin());
    faces.resize(start.back());
    std::vector<std::uint64_t> at(start.begin(), start.end() - 1);
    for (std::size_t f = 0; f < tris.size(); ++f)
      for (std::uint32_t v : tris[f]) faces[at[v]++] = static_cast<std::uint32_t>(f);
  }
};

// Triangles of the input (quads split along their better diagonal, as the quality measure does).
std::vector<Tri> input_triangles(const Mesh& mesh) {
  std::vector<Tri> tris = mesh.triangles;
  tris.reserve(mesh.triangles.size() + 2 * mesh.quads.size());
  for (const Quad& q : mesh.quads)
    for (const Tri& t : split_quad(mesh.positions, q).triangles) tris.push_back(t);
  return tris;
}

// Splits every vertex whose faces form more than one fan (faces joined across edges with exactly
// two consistently oriented faces) into one vertex per fan. The first fan (holding the vertex's
// lowest face) keeps the vertex; the others get locked copies. Faces with a repeated corner are
// left alone (OpenMesh refuses them; they pass through).
void split_fans(WorkMesh& m, SimplifyStats& stats) {
  const std::size_t nv = m.positions.size();
  const VertexFaces vf(nv, m.triangles);
  // fan_of[c]: the fan (0-based, per vertex) of face corner c = 3 f + i.
  std::vector<std::uint32_t> fan_of(3 * m.triangles.size(), 0);
  std::vector<std::uint32_t> fans(nv, 0);
  std::vector<std::uint8_t> on_boundary(nv, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nv, 4096), [&](const auto& range) {
    struct Entry {
      std::uint32_t u, slot;
      int dir;
    };
    std::vector<Entry> entries;
    std::vector<std::uint32_t> parent;
    for (std::size_t v = range.begin(); v != range.end(); ++v) {
      const std::uint64_t b = vf.start[v], e = vf.start[v + 1];
      const std::size_t n = e - b;
      if (n == 0) continue;
      entries.clear();
      parent.resize(n);
      std::iota(parent.begin(), parent.end(), 0u);
      for (std::size_t s = 0; s < n; ++s) {
        const Tri& t = m.triangles[vf.faces[b + s]];
        for (int i = 0; i < 3; ++i)
          if (t[i] == v) {
            entries.push_back({t[(i + 1) % 3], static_cast<std::uint32_t>(s), +1});
            entries.push_back({t[(i + 2) % 3], static_cast<std::uint32_t>(s), -1});
            break;
          }
      }
      std::sort(entries.begin(), entries.end(), [](const Entry& x, const Entry& y) {
        return x.u < y.u || (x.u == y.u && x.slot < y.slot);
      });
      auto find = [&](std::uint32_t x) {
        while (parent[x] != x) x = parent[x] = parent[parent[x]];
        return x;
      };
      for (std::size_t i = 0; i < entries.size();) {
        std::size_t j = i;
        while (j < entries.size() && entries[j].u == entries[i].u) ++j;
        if (j - i == 1) on_boundary[v] = 1;
        if (j - i == 2 && entries[i].dir != entries[i + 1].dir) {
          const std::uint32_t x = find(entries[i].slot), y = find(entries[i + 1].slot);
          if (x != y) parent[std::max(x, y)] = std::min(x, y);
        }
        i = j;
      }
      // Fans numbered in order of their lowest face (slots are in ascending face order).
      std::vector<std::uint32_t> label(n, ~0u);
      std::uint32_t count = 0;
      for (std::size_t s = 0; s < n; ++s) {
        const std::uint32_t r = find(static_cast<std::uint32_t>(s));
        if (label[r] == ~0u) label[r] = count++;
        const std::uint32_t f = vf.faces[b + s];
        const Tri& t = m.triangles[f];
        for (int i = 0; i < 3; ++i)
          if (t[i] == v) fan_of[3 * std::size_t{f} + i] = label[r];
      }
      fans[v] = count;
    }
  });
  for (std::size_t v = 0; v < nv; ++v) stats.boundary_vertices += on_boundary[v];
  // Copies are numbered after the input's vertices, in vertex order.
  std::vector<std::uint64_t> first_copy(nv + 1, 0);
  for (std::size_t v = 0; v < nv; ++v)
    first_copy[v + 1] = first_copy[v] + (fans[v] > 1 ? fans[v] - 1 : 0);
  const std::uint64_t copies = first_copy[nv];
  if (copies == 0) return;
  if (nv + copies > std::numeric_limits<std::uint32_t>::max())
    throw CapacityError("simplify: too many vertices after splitting non-manifold vertices");
  m.group.assign(nv + copies, -1);
  m.locked.resize(nv + copies, 0);
  m.positions.resize(nv + copies);
  m.origin.resize(nv + copies);
  for (std::size_t v = 0; v < nv; ++v) {
    if (fans[v] <= 1) continue;
    ++stats.split_vertices;
    m.group[v] = static_cast<std::int32_t>(v);
    m.locked[v] = 1;
    for (std::uint32_t k = 1; k < fans[v]; ++k) {
      const std::size_t c = nv + first_copy[v] + k - 1;
      m.positions[c] = m.positions[v];
      m.origin[c] = m.origin[v];
      m.group[c] = static_cast<std::int32_t>(v);
      m.locked[c] = 1;
    }
  }
  for (std::size_t f = 0; f < m.triangles.size(); ++f)
    for (int i = 0; i < 3; ++i) {
      const std::uint32_t v = m.triangles[f][i];
      const std::uint32_t k = fan_of[3 * f + i];
      if (k > 0) m.triangles[f][i] = static_cast<std::uint32_t>(nv + first_copy[v] + k - 1);
    }
  stats.split_copies = copies;
}

// Every vertex's quadric: the planes of its faces, each with weight 1, and their area vectors.
void initial_quadrics(WorkMesh& m) {
  std::vector<Quadric> planes(m.triangles.size());
  tbb::parallel_for(std::size_t{0}, m.triangles.size(), [&](std::size_t f) {
    const Tri& t = m.triangles[f];
    const Vec3d& a = m.positions[t[0]];
    Vec3d n = cross(sub(m.positions[t[1]], a), sub(m.positions[t[2]], a));
    const double len = std::sqrt(dot(n, n));
    if (!(len > 0)) return;  // a degenerate face has no plane
    const Vec3d area{n[0] / 2, n[1] / 2, n[2] / 2};
    for (double& c : n) c /= len;
    planes[f] = Quadric::plane(n, -dot(n, a));
    planes[f].area = area;
    planes[f].area_sum = len / 2;
  });
  const VertexFaces vf(m.positions.size(), m.triangles);
  m.quadrics.assign(m.positions.size(), Quadric{});
  tbb::parallel_for(std::size_t{0}, m.positions.size(), [&](std::size_t v) {
    for (std::uint64_t i = vf.start[v]; i < vf.start[v + 1]; ++i)
      m.quadrics[v] += planes[vf.faces[i]];
  });
}

Vec3d centroid(const WorkMesh& m, const Tri& t) {
  Vec3d c{0, 0, 0};
  for (std::uint32_t v : t)
    for (int a = 0; a < 3; ++a) c[a] += m.positions[v][a] / 3;
  return c;
}

// The points the error bound holds the result to: every vertex (on its first face), every
// edge's midpoint (on the first face that has the edge) and every face's centroid.
void error_points(WorkMesh& m) {
  std::vector<std::int64_t> first(m.positions.size(), -1);
  for (std::size_t f = 0; f < m.triangles.size(); ++f)
    for (std::uint32_t v : m.triangles[f])
      if (first[v] < 0) first[v] = static_cast<std::int64_t>(f);
  for (std::size_t v = 0; v < m.positions.size(); ++v)
    if (first[v] >= 0) {
      m.points.push_back(m.positions[v]);
      m.point_face.push_back(static_cast<std::uint32_t>(first[v]));
    }
  for (std::size_t f = 0; f < m.triangles.size(); ++f) {
    const Tri& t = m.triangles[f];
    m.points.push_back(centroid(m, t));
    m.point_face.push_back(static_cast<std::uint32_t>(f));
    for (int i = 0; i < 3; ++i) {
      // Each edge once: from the face that runs it from its lower to its higher vertex, or
      // from both faces where orientations disagree (a harmless duplicate).
      const std::uint32_t a = t[i], b = t[(i + 1) % 3];
      if (a > b) continue;
      const Vec3d& pa = m.positions[a];
      const Vec3d& pb = m.positions[b];
      m.points.push_back({(pa[0] + pb[0]) / 2, (pa[1] + pb[1]) / 2, (pa[2] + pb[2]) / 2});
      m.point_face.push_back(static_cast<std::uint32_t>(f));
    }
  }
}

// A grid of cubic cells over the mesh's box; `shift` moves it by half a cell (one more cell per
// axis), so that its cells straddle the unshifted grid's seams.
struct Grid {
  Vec3d lo{0, 0, 0};
  double cell = 1;
  Index3 n{1, 1, 1};

  std::int64_t cell_of(const Vec3d& p) const {
    Index3 c;
    for (int a = 0; a < 3; ++a)
      c[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor((p[a] - lo[a]) / cell)),
                                      0, n[a] - 1);
    return (c[2] * n[1] + c[1]) * n[0] + c[0];
  }
  std::int64_t total() const { return n[0] * n[1] * n[2]; }
};

// Halves the cell size until the occupied cells average at most kRegionFaces faces.
Grid plan_grid(const WorkMesh& m) {
  Vec3d lo{HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (const Tri& t : m.triangles)
    for (std::uint32_t v : t)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], m.positions[v][a]);
        hi[a] = std::max(hi[a], m.positions[v][a]);
      }
  Grid g;
  g.lo = lo;
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-30});
  std::vector<Vec3d> centroids(m.triangles.size());
  for (std::size_t f = 0; f < m.triangles.size(); ++f) centroids[f] = centroid(m, m.triangles[f]);
  for (int level = 0;; ++level) {
    g.cell = extent / static_cast<double>(std::int64_t{1} << level);
    for (int a = 0; a < 3; ++a)
      g.n[a] =
          std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil((hi[a] - lo[a]) / g.cell)));
    if (m.triangles.size() <= kRegionFaces || level >= 10) return g;
    std::vector<std::uint32_t> count(g.total(), 0);
    std::int64_t occupied = 0;
    for (const Vec3d& c : centroids) occupied += count[g.cell_of(c)]++ == 0;
    if (m.triangles.size() <= kRegionFaces * static_cast<std::uint64_t>(occupied)) return g;
  }
}

// Vertices whose faces lie in more than one cell of the grid.
std::uint64_t count_shared(const WorkMesh& m, const Grid& g) {
  // first[v]: the cell of v's first face, or -1; -2 once a second cell is seen.
  std::vector<std::int64_t> first(m.positions.size(), -1);
  std::uint64_t shared = 0;
  for (const Tri& t : m.triangles) {
    const std::int64_t c = g.cell_of(centroid(m, t));
    for (std::uint32_t v : t) {
      if (first[v] == -1) {
        first[v] = c;
      } else if (first[v] >= 0 && first[v] != c) {
        first[v] = -2;
        ++shared;
      }
    }
  }
  return shared;
}

Grid shifted(const Grid& g) {
  Grid s = g;
  for (int a = 0; a < 3; ++a) {
    s.lo[a] -= 0.5 * g.cell;
    s.n[a] = g.n[a] + 1;
  }
  return s;
}

struct PassResult {
  WorkMesh mesh;
  std::int64_t regions = 0;
};

// The cost ceiling of the next round: the `k`-th smallest key among the regions' waiting edges,
// estimated from an even sample of at most 2^16 keys (in region order, so deterministic).
double round_ceiling(const std::vector<std::vector<double>>& costs, std::uint64_t k,
                     std::uint64_t total) {
  const std::uint64_t step = std::max<std::uint64_t>(1, total / 65536);
  std::vector<double> sample;
  sample.reserve(total / step + 1);
  std::uint64_t i = 0;
  for (const auto& c : costs)
    for (double x : c)
      if (i++ % step == 0) sample.push_back(x);
  const std::size_t at = std::min<std::size_t>(sample.size() - 1, k / step);
  std::nth_element(sample.begin(), sample.begin() + static_cast<std::ptrdiff_t>(at), sample.end());
  return sample[at];
}

// One pass: every occupied cell of `grid` is a region, simplified on its own thread with what it
// shares with other regions locked. With a target, the regions collapse in rounds under a common
// cost ceiling, each round asking for half the faces still to go, so that together they follow
// nearly the order of one heap over the whole mesh (a per-region face quota would spread the
// reduction evenly instead of where it costs least); without one (an error bound only), each
// region collapses all it may. The regions are then put back together in cell order.
PassResult run_pass(const WorkMesh& in, const Grid& grid, std::uint64_t target,
                    const RegionOptions& base, Progress* progress, SimplifyStats& stats) {
  const std::int64_t cells = grid.total();
  std::vector<std::uint64_t> start(cells + 1, 0);
  std::vector<std::int64_t> cell_of(in.triangles.size());
  tbb::parallel_for(std::size_t{0}, in.triangles.size(), [&](std::size_t f) {
    cell_of[f] = grid.cell_of(centroid(in, in.triangles[f]));
  });
  for (std::int64_t c : cell_of) ++start[c + 1];
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<std::uint32_t> faces(in.triangles.size());
  std::vector<std::uint32_t> local_face(in.triangles.size());  // index within its region
  {
    std::vector<std::uint64_t> at(start.begin(), start.end() - 1);
    for (std::size_t f = 0; f < cell_of.size(); ++f) {
      local_face[f] = static_cast<std::uint32_t>(at[cell_of[f]] - start[cell_of[f]]);
      faces[at[cell_of[f]]++] = static_cast<std::uint32_t>(f);
    }
  }
  std::vector<std::int64_t> occupied;
  for (std::int64_t c = 0; c < cells; ++c)
    if (start[c + 1] > start[c]) occupied.push_back(c);
  const std::size_t nr = occupied.size();

  // Regions hold their vertices in ascending input order.
  std::vector<std::vector<std::uint32_t>> ids(nr);
  tbb::parallel_for(std::size_t{0}, nr, [&](std::size_t r) {
    const std::int64_t c = occupied[r];
    auto& v = ids[r];
    for (std::uint64_t i = start[c]; i < start[c + 1]; ++i)
      for (std::uint32_t x : in.triangles[faces[i]]) v.push_back(x);
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  });

  // The error bound's points go with their faces (in point order within each region).
  std::vector<std::int64_t> region_of_cell(cells, -1);
  for (std::size_t r = 0; r < nr; ++r) region_of_cell[occupied[r]] = static_cast<std::int64_t>(r);
  std::vector<std::vector<std::uint32_t>> region_points(nr);
  for (std::size_t i = 0; i < in.points.size(); ++i)
    region_points[region_of_cell[cell_of[in.point_face[i]]]].push_back(
        static_cast<std::uint32_t>(i));

  std::vector<std::optional<RegionSimplifier>> sims(nr);
  tbb::parallel_for(std::size_t{0}, nr, std::size_t{1}, [&](std::size_t r) {
    // The pass's set-up reports nothing (a 256^3 gyroid's went 0.9 s without a report, 2 cores):
    // a region about to be made looks for a cancel first.
    progress_check(progress);
    const std::int64_t c = occupied[r];
    Region reg;
    for (std::uint32_t i : region_points[r]) {
      reg.points.push_back(in.points[i]);
      reg.point_face.push_back(local_face[in.point_face[i]]);
    }
    reg.id = std::move(ids[r]);
    reg.positions.reserve(reg.id.size());
    for (std::uint32_t v : reg.id) {
      reg.positions.push_back(in.positions[v]);
      reg.quadrics.push_back(in.quadrics[v]);
      reg.locked.push_back(in.locked[v]);
      if (!in.group.empty()) reg.group.push_back(in.group[v]);
    }
    reg.triangles.reserve(start[c + 1] - start[c]);
    auto local = [&](std::uint32_t v) {
      return static_cast<std::uint32_t>(std::lower_bound(reg.id.begin(), reg.id.end(), v) -
                                        reg.id.begin());
    };
    for (std::uint64_t i = start[c]; i < start[c + 1]; ++i) {
      const Tri& t = in.triangles[faces[i]];
      reg.triangles.push_back({local(t[0]), local(t[1]), local(t[2])});
    }
    sims[r].emplace(std::move(reg), base);
  });

  // Progress (Stage::Simplify, begun by each pass in its share of the run's): the faces still to go
  // before the target, as each round of collapses removes them (without a target: one per region
  // collapsed), then one per region finished. Regions check for cancel within a round too
  // (RegionSimplifier).
  const std::uint64_t faces_in = in.triangles.size();
  const std::uint64_t to_go = target == 0 ? nr : (faces_in > target ? faces_in - target : 0);
  progress_begin(progress, Stage::Simplify, static_cast<std::int64_t>(to_go + nr));
  std::uint64_t reported = 0;  // of to_go
  if (target == 0) {
    tbb::parallel_for(std::size_t{0}, nr, std::size_t{1}, [&](std::size_t r) {
      sims[r]->collapse(HUGE_VAL, ~std::uint64_t{0}, progress);
      progress_advance(progress);
    });
    reported = to_go;
  } else {
    std::vector<std::vector<double>> costs(nr);
    std::vector<std::uint64_t> quota(nr), made(nr);
    // A round whose edges were all refused asks for more the next time.
    std::uint64_t widen = 1;
    for (;;) {
      std::uint64_t live = 0;
      for (const auto& sim : sims) live += sim->faces();
      if (progress && faces_in > live && faces_in - live > reported) {
        progress->advance(static_cast<std::int64_t>(faces_in - live - reported));
        reported = faces_in - live;
      }
      if (live <= target) break;
      tbb::parallel_for(std::size_t{0}, nr, [&](std::size_t r) {
        costs[r].clear();
        sims[r]->costs(costs[r]);
      });
      std::uint64_t waiting = 0;
      for (const auto& c : costs) waiting += c.size();
      if (waiting == 0) break;
      // Each collapse takes two faces; asking for half of what is left keeps the ceiling low
      // enough that collapses raising their neighbours' keys rarely overshoot.
      const std::uint64_t k =
          std::min(waiting, std::max<std::uint64_t>(1, (live - target) / 4) * widen);
      const double ceiling = round_ceiling(costs, k, waiting);
      // Quotas in region order, capped so that the round never takes more than k collapses.
      std::uint64_t left = k;
      for (std::size_t r = 0; r < nr; ++r) {
        const auto below = static_cast<std::uint64_t>(std::count_if(
            costs[r].begin(), costs[r].end(), [&](double x) { return x <= ceiling; }));
        quota[r] = std::min(below, left);
        left -= quota[r];
      }
      tbb::parallel_for(std::size_t{0}, nr, std::size_t{1}, [&](std::size_t r) {
        made[r] = quota[r] ? sims[r]->collapse(ceiling, quota[r], progress) : 0;
      });
      if (std::accumulate(made.begin(), made.end(), std::uint64_t{0}) > 0) {
        widen = 1;
      } else {
        if (k >= waiting) break;  // every waiting edge was tried and refused
        widen *= 4;
      }
    }
  }

  // The rounds may stop short of the target (edges refused): their share counts as done.
  if (progress && to_go > reported) progress->advance(static_cast<std::int64_t>(to_go - reported));
  std::vector<Region> out(nr);
  tbb::parallel_for(std::size_t{0}, nr, std::size_t{1}, [&](std::size_t r) {
    progress_check(progress);
    out[r] = sims[r]->finish();
    progress_advance(progress);
  });

  // Back together. A vertex shared by regions was locked in each, so all give the same position;
  // each adds what it collapsed into it to its quadric.
  const std::size_t nv = in.positions.size();
  std::vector<std::uint8_t> used(nv, 0);
  std::vector<Vec3d> pos = in.positions;
  std::vector<Quadric> quad = in.quadrics;
  for (std::size_t r = 0; r < nr; ++r) {
    const Region& reg = out[r];
    for (std::size_t i = 0; i < reg.id.size(); ++i) {
      const std::uint32_t v = reg.id[i];
      if (!used[v]) {
        pos[v] = reg.positions[i];
        quad[v] = reg.quadrics[i];
      } else {
        Quadric added = reg.quadrics[i];
        added -= in.quadrics[v];
        quad[v] += added;
      }
      used[v] = 1;
    }
    const RegionStats& s = sims[r]->stats();
    stats.collapses += s.collapses;
    stats.flips += s.flips;
    stats.relaxed += s.relaxed;
    stats.cleanup += s.cleanup;
    stats.unlinked_faces += s.unlinked_faces;
  }
  PassResult res;
  res.regions = static_cast<std::int64_t>(nr);
  std::vector<std::uint32_t> index(nv, 0);
  WorkMesh& m = res.mesh;
  for (std::size_t v = 0; v < nv; ++v) {
    if (!used[v]) continue;
    index[v] = static_cast<std::uint32_t>(m.positions.size());
    m.positions.push_back(pos[v]);
    m.quadrics.push_back(quad[v]);
    m.locked.push_back(in.locked[v]);
    m.origin.push_back(in.origin[v]);
    if (!in.group.empty()) m.group.push_back(in.group[v]);
  }
  for (const Region& reg : out) {
    const auto base_face = static_cast<std::uint32_t>(m.triangles.size());
    for (const Tri& t : reg.triangles)
      m.triangles.push_back({index[reg.id[t[0]]], index[reg.id[t[1]]], index[reg.id[t[2]]]});
    for (std::size_t i = 0; i < reg.points.size(); ++i) {
      m.points.push_back(reg.points[i]);
      m.point_face.push_back(base_face + reg.point_face[i]);
    }
  }
  return res;
}

// The simplified mesh: surviving vertices with the input vertex each one is, and their quadrics.
struct Welded {
  std::vector<Vec3d> positions;
  std::vector<Quadric> quadrics;
  std::vector<std::uint32_t> origin;
  std::vector<Tri> triangles;
};

// Copies of a split vertex become one vertex again (they never moved); unreferenced vertices go.
Welded weld(const WorkMesh& m) {
  const std::size_t nv = m.positions.size();
  std::vector<std::uint32_t> rep(nv);
  std::iota(rep.begin(), rep.end(), 0u);
  if (!m.group.empty()) {
    // Groups are input vertex indices, which may exceed the surviving vertex count.
    const std::int32_t groups = *std::max_element(m.group.begin(), m.group.end()) + 1;
    std::vector<std::int64_t> by_group(static_cast<std::size_t>(std::max(groups, 0)), -1);
    for (std::size_t v = 0; v < nv; ++v) {
      const std::int32_t g = m.group[v];
      if (g < 0) continue;
      if (by_group[g] < 0) by_group[g] = static_cast<std::int64_t>(v);
      rep[v] = static_cast<std::uint32_t>(by_group[g]);
    }
  }
  std::vector<std::uint8_t> used(nv, 0);
  for (const Tri& t : m.triangles)
    for (std::uint32_t v : t) used[rep[v]] = 1;
  std::vector<std::uint32_t> index(nv, 0);
  Welded out;
  for (std::size_t v = 0; v < nv; ++v)
    if (used[v]) {
      index[v] = static_cast<std::uint32_t>(out.positions.size());
      out.positions.push_back(m.positions[v]);
      out.origin.push_back(m.origin[v]);
      out.quadrics.push_back(m.quadrics.empty() ? Quadric{} : m.quadrics[v]);
    }
  // A welded vertex's quadric: the copies' planes together.
  if (!m.group.empty() && !m.quadrics.empty())
    for (std::size_t v = 0; v < nv; ++v)
      if (rep[v] != v && used[rep[v]]) out.quadrics[index[rep[v]]] += m.quadrics[v];
  out.triangles.reserve(m.triangles.size());
  for (const Tri& t : m.triangles)
    out.triangles.push_back({index[rep[t[0]]], index[rep[t[1]]], index[rep[t[2]]]});
  return out;
}

void area_weighted_normals(Mesh& mesh) {
  std::vector<Vec3d> acc(mesh.positions.size(), Vec3d{0, 0, 0});
  for (const Tri& t : mesh.triangles) {
    Vec3d p[3];
    for (int i = 0; i < 3; ++i)
      for (int a = 0; a < 3; ++a) p[i][a] = mesh.positions[t[i]][a];
    const Vec3d n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    for (std::uint32_t v : t)
      for (int a = 0; a < 3; ++a) acc[v][a] += n[a];
  }
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t v = 0; v < acc.size(); ++v) {
    const double len = std::sqrt(dot(acc[v], acc[v]));
    for (int a = 0; a < 3; ++a)
      mesh.normals[v][a] = len > 0 ? static_cast<float>(acc[v][a] / len) : 0.0f;
  }
}

// Splits, computes quadrics (unless the caller gave them) and error points, and runs the two
// passes toward `target` faces (0: the error bound alone).
Welded simplify_work(WorkMesh m, std::uint64_t target, const SimplifyOptions& options,
                     SimplifyStats& stats, bool boundary_allowance = false) {
  const std::uint64_t faces = m.triangles.size();
  const bool carried = !m.quadrics.empty();
  if (m.origin.empty()) {
    m.origin.resize(m.positions.size());
    std::iota(m.origin.begin(), m.origin.end(), 0u);
  }
  if (faces == 0 || (target >= faces && options.max_error == 0)) {
    if (!carried) initial_quadrics(m);
    return weld(m);
  }
  const std::uint64_t boundary_before = stats.boundary_vertices;
  split_fans(m, stats);
  if (boundary_allowance && target > 0 && target < faces) {
    // The piece's boundary is locked here and simplified by a later pass: aim above the target
    // by what it holds, as the first pass below does for its own seams.
    const double keep = static_cast<double>(target) / static_cast<double>(faces);
    const double held =
        kSeamFaces * static_cast<double>(stats.boundary_vertices - boundary_before) * (1 - keep);
    target = std::min<std::uint64_t>(faces, target + static_cast<std::uint64_t>(held));
  }
  if (carried) {
    // Copies made by the split start with no planes; weld() adds theirs to the original's.
    m.quadrics.resize(m.positions.size());
  } else {
    initial_quadrics(m);
  }
  if (options.max_error > 0) error_points(m);
  RegionOptions ro;
  ro.max_error = options.max_error;
  ro.min_quality = options.min_quality;
  ro.relax_passes = options.relax ? ro.relax_passes : 0;
  const Grid grid = plan_grid(m);
  // The first pass leaves its seams (vertices shared by regions) for the second, whose regions
  // straddle them; it stops short of the target by what those seams are expected to hold, so
  // that the region interiors are not simplified past where the whole mesh would be.
  std::uint64_t target1 = target;
  if (target > 0) {
    const double keep = static_cast<double>(target) / static_cast<double>(faces);
    const double held = kSeamFaces * static_cast<double>(count_shared(m, grid)) * (1 - keep);
    target1 = std::min<std::uint64_t>(faces, target + static_cast<std::uint64_t>(held));
  }
  // Both passes report as one stage, each through its share, sized by the units it counts (the
  // faces it removes, one per region) with as many regions in the second as in the first.
  std::optional<Progress> first_pass, second_pass;
  if (options.progress) {
    const double regions = static_cast<double>(faces / kRegionFaces + 1);
    const double first = static_cast<double>(target > 0 ? faces - target1 : 0) + regions;
    const double second = static_cast<double>(target > 0 ? target1 - target : 0) + regions;
    const double split = first / (first + second);
    first_pass.emplace(*options.progress, 0.0, split);
    second_pass.emplace(*options.progress, split, 1.0);
  }
  const auto share = [](std::optional<Progress>& p) { return p ? &*p : nullptr; };
  const std::uint64_t unlinked_before = stats.unlinked_faces;
  PassResult p1 = run_pass(m, grid, target1, ro, share(first_pass), stats);
  stats.regions += p1.regions;
  // Faces OpenMesh cannot link pass through both passes: counted once, not once per pass.
  const std::uint64_t unlinked_first = stats.unlinked_faces - unlinked_before;
  stats.unlinked_faces = unlinked_before;
  PassResult p2 = run_pass(p1.mesh, shifted(grid), target, ro, share(second_pass), stats);
  stats.unlinked_faces =
      unlinked_before + std::max(unlinked_first, stats.unlinked_faces - unlinked_before);
  stats.seam_regions += p2.regions;
  return weld(p2.mesh);
}

void check_options(const SimplifyOptions& options) {
  if (!(options.ratio >= 0) || options.ratio > 1)
    throw InputError("simplify: the ratio must be in (0, 1], got " + number_text(options.ratio));
  if (!(options.max_error >= 0) || !std::isfinite(options.max_error))
    throw InputError("simplify: the maximum error must be a finite number >= 0");
  if (!(options.min_quality >= 0) || options.min_quality > 1)
    throw InputError("simplify: the quality floor must be in [0, 1]");
}

}  // namespace

std::string target_missed(const SimplifyStats& stats) {
  const std::uint64_t target = stats.target_faces, got = stats.faces_after;
  const std::uint64_t off = got > target ? got - target : target - got;
  if (target == 0 || off <= std::max<std::uint64_t>(target / 10, 10)) return "";
  const std::string percent = std::to_string(static_cast<long>(
      std::lround(100.0 * static_cast<double>(off) / static_cast<double>(target))));
  if (got > target)
    return "simplification stopped at " + std::to_string(got) + " triangles, " + percent +
           "% above its target of " + std::to_string(target) +
           ": no collapse left kept the topology, the border, the surface's orientation and the "
           "triangles' shape";
  // The cleanup's collapses of triangles below the quality floor come after the count is
  // reached: a raised --min-quality can take it a tenth below (gyroid 32, MC, half, floor 1:
  // 8,100 for 9,338), which was said nowhere.
  return "simplification ended at " + std::to_string(got) + " triangles, " + percent +
         "% below its target of " + std::to_string(target) +
         ": the cleanup collapsed triangles below the quality floor (--min-quality) after the "
         "target was reached";
}

Mesh simplify(const Mesh& mesh, const SimplifyOptions& options, SimplifyStats* stats_out) {
  check_options(options);
  if (options.ratio == 0 && options.faces == 0 && options.max_error == 0)
    throw InputError("simplify: give a ratio, a face count or a maximum error");
  check_face_indices(mesh);
  for (const Vec3f& p : mesh.positions)
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
      throw InputError("simplify: the mesh has a vertex position that is not a finite number");

  SimplifyStats stats;
  WorkMesh m;
  m.triangles = input_triangles(mesh);
  m.positions.reserve(mesh.positions.size());
  for (const Vec3f& p : mesh.positions) m.positions.push_back({p[0], p[1], p[2]});
  m.locked.assign(m.positions.size(), 0);
  const std::uint64_t faces = m.triangles.size();
  stats.faces_before = faces;
  {
    std::vector<std::uint8_t> used(mesh.positions.size(), 0);
    for (const Tri& t : m.triangles)
      for (std::uint32_t v : t) used[v] = 1;
    stats.vertices_before = std::count(used.begin(), used.end(), 1);
  }
  std::uint64_t target = options.faces;
  if (target == 0 && options.ratio > 0)
    target = static_cast<std::uint64_t>(std::llround(options.ratio * static_cast<double>(faces)));
  if (options.faces > 0 || options.ratio > 0) target = std::max<std::uint64_t>(target, 1);
  stats.target_faces = target;

  const Welded w = simplify_work(std::move(m), target, options, stats);
  Mesh result;
  result.positions.reserve(w.positions.size());
  for (const Vec3d& p : w.positions)
    result.positions.push_back(
        {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])});
  result.triangles = w.triangles;
  if (!mesh.normals.empty()) area_weighted_normals(result);
  stats.faces_after = result.triangles.size();
  stats.vertices_after = result.positions.size();
  if (stats_out) *stats_out = stats;
  return result;
}

MeshPiece simplify_piece(MeshPiece piece, std::uint64_t target_faces,
                         const SimplifyOptions& options, SimplifyStats* stats,
                         bool boundary_allowance) {
  check_options(options);
  if (piece.keys.size() != piece.positions.size() ||
      (!piece.quadrics.empty() && piece.quadrics.size() != piece.positions.size()))
    throw InputError("simplify_piece: keys and quadrics must match the vertices");
  for (const Tri& t : piece.triangles)
    for (std::uint32_t v : t)
      if (v >= piece.positions.size())
        throw InputError("simplify_piece: a face references a vertex past the end");
  SimplifyStats local;
  WorkMesh m;
  m.positions = std::move(piece.positions);
  m.quadrics = std::move(piece.quadrics);
  m.triangles = std::move(piece.triangles);
  m.locked.assign(m.positions.size(), 0);
  local.faces_before = m.triangles.size();
  const Welded w = simplify_work(std::move(m), target_faces, options, local, boundary_allowance);
  MeshPiece out;
  out.positions = w.positions;
  out.quadrics = w.quadrics;
  out.triangles = w.triangles;
  out.keys.reserve(w.origin.size());
  for (std::uint32_t o : w.origin) out.keys.push_back(piece.keys[o]);
  if (stats) {
    stats->faces_before += local.faces_before;
    stats->faces_after += out.triangles.size();
    stats->regions += local.regions;
    stats->seam_regions += local.seam_regions;
    stats->boundary_vertices += local.boundary_vertices;
    stats->split_vertices += local.split_vertices;
    stats->split_copies += local.split_copies;
    stats->unlinked_faces += local.unlinked_faces;
    stats->collapses += local.collapses;
    stats->flips += local.flips;
    stats->relaxed += local.relaxed;
    stats->cleanup += local.cleanup;
  }
  return out;
}

}  // namespace isotile
