#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <optional>
#include <random>

#include "core/errors.h"
#include "core/mesh/mesh_topology.h"

namespace isotile {
namespace {

// Outward-facing tetrahedron.
Mesh tetrahedron() {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

// Unit cube, vertex x + 2y + 4z, faces wound outward.
Mesh cube(bool quads) {
  Mesh m;
  for (int i = 0; i < 8; ++i) {
    m.positions.push_back({float(i & 1), float((i >> 1) & 1), float((i >> 2) & 1)});
  }
  const std::vector<Quad> faces = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                   {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const Quad& q : faces) {
    if (quads) {
      m.quads.push_back(q);
    } else {
      m.triangles.push_back({q[0], q[1], q[2]});
      m.triangles.push_back({q[0], q[2], q[3]});
    }
  }
  return m;
}

// An n x m grid whose rows and columns wrap around: a torus.
Mesh torus(std::uint32_t n, std::uint32_t m, bool quads) {
  Mesh mesh;
  for (std::uint32_t i = 0; i < n; ++i) {
    for (std::uint32_t j = 0; j < m; ++j) {
      const double u = 2 * M_PI * i / n, v = 2 * M_PI * j / m;
      mesh.positions.push_back({float((3 + std::cos(v)) * std::cos(u)),
                                float((3 + std::cos(v)) * std::sin(u)), float(std::sin(v))});
    }
  }
  for (std::uint32_t i = 0; i < n; ++i) {
    for (std::uint32_t j = 0; j < m; ++j) {
      const std::uint32_t a = i * m + j, b = i * m + (j + 1) % m, c = ((i + 1) % n) * m + j,
                          d = ((i + 1) % n) * m + (j + 1) % m;
      if (quads) {
        mesh.quads.push_back({a, b, d, c});
      } else {
        mesh.triangles.push_back({a, b, d});
        mesh.triangles.push_back({a, d, c});
      }
    }
  }
  return mesh;
}

TEST(MeshTopology, Tetrahedron) {
  const TopologyStats s = mesh_topology(tetrahedron());
  EXPECT_EQ(s.vertices, 4u);
  EXPECT_EQ(s.unreferenced_vertices, 0u);
  EXPECT_EQ(s.edges, 6u);
  EXPECT_EQ(s.faces, 4u);
  EXPECT_EQ(s.boundary_edges, 0u);
  EXPECT_EQ(s.nonmanifold_edges, 0u);
  EXPECT_EQ(s.nonmanifold_vertices, 0u);
  EXPECT_EQ(s.inconsistently_oriented_edges, 0u);
  EXPECT_EQ(s.euler, 2);
  EXPECT_EQ(s.components, 1u);
  EXPECT_TRUE(s.closed);
  EXPECT_TRUE(s.watertight);
}

TEST(MeshTopology, FlippedFace) {
  Mesh m = tetrahedron();
  std::swap(m.triangles[3][1], m.triangles[3][2]);
  const TopologyStats s = mesh_topology(m);
  // Each of the flipped face's three edges now runs the same way in both of its faces.
  EXPECT_EQ(s.inconsistently_oriented_edges, 3u);
  EXPECT_EQ(s.boundary_edges, 0u);
  EXPECT_EQ(s.euler, 2);
  EXPECT_TRUE(s.closed);
}

TEST(MeshTopology, CubeOfTriangles) {
  const TopologyStats s = mesh_topology(cube(false));
  EXPECT_EQ(s.vertices, 8u);
  EXPECT_EQ(s.edges, 18u);
  EXPECT_EQ(s.faces, 12u);
  EXPECT_EQ(s.euler, 2);
  EXPECT_EQ(s.boundary_edges, 0u);
  EXPECT_EQ(s.inconsistently_oriented_edges, 0u);
  EXPECT_EQ(s.nonmanifold_vertices, 0u);
  EXPECT_EQ(s.components, 1u);
  EXPECT_TRUE(s.closed);
}

TEST(MeshTopology, CubeOfQuads) {
  const TopologyStats s = mesh_topology(cube(true));
  EXPECT_EQ(s.vertices, 8u);
  EXPECT_EQ(s.edges, 12u);
  EXPECT_EQ(s.faces, 6u);
  EXPECT_EQ(s.euler, 2);
  EXPECT_EQ(s.boundary_edges, 0u);
  EXPECT_EQ(s.inconsistently_oriented_edges, 0u);
  EXPECT_EQ(s.nonmanifold_vertices, 0u);
  EXPECT_TRUE(s.closed);
}

TEST(MeshTopology, SingleTriangle) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}};
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.vertices, 3u);
  EXPECT_EQ(s.edges, 3u);
  EXPECT_EQ(s.boundary_edges, 3u);
  EXPECT_EQ(s.border_boundary_edges, 0u);
  EXPECT_EQ(s.nonmanifold_vertices, 0u);
  EXPECT_EQ(s.euler, 1);
  EXPECT_EQ(s.components, 1u);
  EXPECT_FALSE(s.closed);
  EXPECT_FALSE(s.watertight);
}

TEST(MeshTopology, TetrahedraSharingOneVertex) {
  Mesh m = tetrahedron();
  m.positions.push_back({-1, 0, 0});
  m.positions.push_back({0, -1, 0});
  m.positions.push_back({0, 0, -1});
  // The point reflection of the first one, meeting it only at vertex 0.
  m.triangles.push_back({0, 5, 4});
  m.triangles.push_back({0, 4, 6});
  m.triangles.push_back({0, 6, 5});
  m.triangles.push_back({4, 5, 6});
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.vertices, 7u);
  EXPECT_EQ(s.edges, 12u);
  EXPECT_EQ(s.faces, 8u);
  EXPECT_EQ(s.euler, 3);
  EXPECT_EQ(s.nonmanifold_vertices, 1u);
  EXPECT_EQ(s.nonmanifold_edges, 0u);
  EXPECT_EQ(s.boundary_edges, 0u);
  EXPECT_EQ(s.inconsistently_oriented_edges, 0u);
  EXPECT_EQ(s.components, 1u);
  EXPECT_TRUE(s.closed);
}

TEST(MeshTopology, BowtieOfTwoTriangles) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
  m.triangles = {{0, 1, 2}, {0, 3, 4}};
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.nonmanifold_vertices, 1u);
  EXPECT_EQ(s.boundary_edges, 6u);
  EXPECT_EQ(s.components, 1u);
  EXPECT_EQ(s.euler, 5 - 6 + 2);
}

TEST(MeshTopology, ThreeTrianglesOnOneEdge) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}};
  m.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.nonmanifold_edges, 1u);
  EXPECT_EQ(s.boundary_edges, 6u);
  EXPECT_EQ(s.edges, 7u);
  EXPECT_EQ(s.vertices, 5u);
  EXPECT_EQ(s.euler, 1);
  // All three faces share the edge at both of its ends: one fan each.
  EXPECT_EQ(s.nonmanifold_vertices, 0u);
  EXPECT_EQ(s.inconsistently_oriented_edges, 0u);  // only manifold edges can be
  EXPECT_FALSE(s.closed);
  EXPECT_FALSE(s.watertight);
}

TEST(MeshTopology, SquareOnTheBorder) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  TopologyOptions options;
  options.border_box = std::array<Vec3f, 2>{Vec3f{0, 0, 0}, Vec3f{1, 1, 1}};
  TopologyStats s = mesh_topology(m, options);
  EXPECT_EQ(s.boundary_edges, 4u);
  EXPECT_EQ(s.border_boundary_edges, 4u);
  EXPECT_FALSE(s.closed);
  EXPECT_TRUE(s.watertight);
  EXPECT_EQ(s.euler, 1);

  // Without a box nothing is border.
  s = mesh_topology(m);
  EXPECT_EQ(s.border_boundary_edges, 0u);
  EXPECT_FALSE(s.watertight);

  // A box the square does not touch.
  options.border_box = std::array<Vec3f, 2>{Vec3f{-1, -1, -1}, Vec3f{2, 2, 2}};
  s = mesh_topology(m, options);
  EXPECT_EQ(s.border_boundary_edges, 0u);
  EXPECT_FALSE(s.watertight);
}

TEST(MeshTopology, BorderNeedsBothEndsOnOneFace) {
  // A on x = 0, B on y = 0, C on both: A-C and B-C lie in a box face, A-B only touches two.
  Mesh m;
  m.positions = {{0, 0.5f, 0.5f}, {0.5f, 0, 0.5f}, {0, 0, 0.5f}};
  m.triangles = {{0, 1, 2}};
  TopologyOptions options;
  options.border_box = std::array<Vec3f, 2>{Vec3f{0, 0, 0}, Vec3f{1, 1, 1}};
  const TopologyStats s = mesh_topology(m, options);
  EXPECT_EQ(s.boundary_edges, 3u);
  EXPECT_EQ(s.border_boundary_edges, 2u);
  EXPECT_FALSE(s.watertight);
}

TEST(MeshTopology, Torus) {
  for (bool quads : {false, true}) {
    SCOPED_TRACE(quads ? "quads" : "triangles");
    const TopologyStats s = mesh_topology(torus(7, 5, quads));
    EXPECT_EQ(s.vertices, 35u);
    EXPECT_EQ(s.edges, quads ? 70u : 105u);
    EXPECT_EQ(s.faces, quads ? 35u : 70u);
    EXPECT_EQ(s.euler, 0);
    EXPECT_EQ(s.boundary_edges, 0u);
    EXPECT_EQ(s.nonmanifold_vertices, 0u);
    EXPECT_EQ(s.inconsistently_oriented_edges, 0u);
    EXPECT_EQ(s.components, 1u);
    EXPECT_TRUE(s.closed);
  }
}

TEST(MeshTopology, LargeTorusAndDisjointCopies) {
  Mesh m = torus(300, 200, false);
  // A second, shifted copy, plus three vertices no face uses.
  const auto n = static_cast<std::uint32_t>(m.positions.size());
  const std::size_t nt = m.triangles.size();
  for (std::uint32_t i = 0; i < n; ++i) {
    Vec3f p = m.positions[i];
    p[0] += 10;
    m.positions.push_back(p);
  }
  for (std::size_t t = 0; t < nt; ++t) {
    const Tri tri = m.triangles[t];
    m.triangles.push_back({tri[0] + n, tri[1] + n, tri[2] + n});
  }
  m.positions.resize(m.positions.size() + 3);
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.vertices, 120000u);
  EXPECT_EQ(s.unreferenced_vertices, 3u);
  EXPECT_EQ(s.edges, 360000u);
  EXPECT_EQ(s.faces, 240000u);
  EXPECT_EQ(s.euler, 0);
  EXPECT_EQ(s.components, 2u);
  EXPECT_TRUE(s.closed);
}

TEST(MeshTopology, DegenerateFacesDoNotCrash) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 0, 1}, {1, 1, 1}, {0, 1, 2}};
  m.quads = {{0, 1, 0, 2}};
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.faces, 4u);
  EXPECT_EQ(s.vertices, 3u);
  EXPECT_EQ(s.components, 1u);
}

TEST(MeshTopology, EmptyMesh) {
  Mesh m;
  m.positions.resize(4);
  const TopologyStats s = mesh_topology(m);
  EXPECT_EQ(s.vertices, 0u);
  EXPECT_EQ(s.unreferenced_vertices, 4u);
  EXPECT_EQ(s.edges, 0u);
  EXPECT_EQ(s.components, 0u);
  EXPECT_EQ(s.euler, 0);
}

TEST(MeshTopology, BadIndex) {
  Mesh m = tetrahedron();
  m.triangles.push_back({0, 1, 4});
  EXPECT_THROW(mesh_topology(m), InputError);
}

// Straightforward reference: an edge map over all half-edges and, per vertex, an O(d^2)
// union-find of its corners. A boundary edge is border when both ends lie on one face of `box`.
TopologyStats reference(const Mesh& m,
                        const std::optional<std::array<Vec3f, 2>>& box = std::nullopt) {
  std::vector<std::vector<std::uint32_t>> faces;
  for (const Tri& t : m.triangles) faces.push_back({t[0], t[1], t[2]});
  for (const Quad& q : m.quads) faces.push_back({q[0], q[1], q[2], q[3]});
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<bool>> edges;  // forward flags
  std::vector<std::vector<std::pair<std::size_t, std::size_t>>> corners(m.positions.size());
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const auto& face = faces[f];
    for (std::size_t i = 0; i < face.size(); ++i) {
      const std::uint32_t a = face[i], b = face[(i + 1) % face.size()];
      edges[{std::min(a, b), std::max(a, b)}].push_back(a <= b);
      corners[a].emplace_back(f, i);
    }
  }
  TopologyStats s;
  s.faces = faces.size();
  s.edges = edges.size();
  auto on_box_face = [&](std::uint32_t a, std::uint32_t b) {
    for (int axis = 0; axis < 3; ++axis) {
      for (int side = 0; side < 2; ++side) {
        const float plane = (*box)[side][axis];
        if (m.positions[a][axis] == plane && m.positions[b][axis] == plane) return true;
      }
    }
    return false;
  };
  for (const auto& [key, dirs] : edges) {
    if (dirs.size() == 1) {
      ++s.boundary_edges;
      if (box && on_box_face(key.first, key.second)) ++s.border_boundary_edges;
    }
    if (dirs.size() > 2) ++s.nonmanifold_edges;
    if (dirs.size() == 2 && dirs[0] == dirs[1]) ++s.inconsistently_oriented_edges;
  }
  std::vector<std::uint32_t> component(m.positions.size());
  std::iota(component.begin(), component.end(), 0u);
  std::function<std::uint32_t(std::uint32_t)> root = [&](std::uint32_t x) {
    return component[x] == x ? x : component[x] = root(component[x]);
  };
  for (const auto& face : faces) {
    for (std::uint32_t v : face) component[root(v)] = root(face[0]);
  }
  for (std::uint32_t v = 0; v < m.positions.size(); ++v) {
    const auto& cs = corners[v];
    if (cs.empty()) {
      ++s.unreferenced_vertices;
      continue;
    }
    ++s.vertices;
    if (root(v) == v) ++s.components;
    auto neighbours = [&](std::pair<std::size_t, std::size_t> c) {
      const auto& face = faces[c.first];
      return std::array<std::uint32_t, 2>{face[(c.second + 1) % face.size()],
                                          face[(c.second + face.size() - 1) % face.size()]};
    };
    std::vector<std::size_t> group(cs.size());
    std::iota(group.begin(), group.end(), 0u);
    // Relabel until stable: simple and obviously right for small degrees.
    for (bool changed = true; changed;) {
      changed = false;
      for (std::size_t i = 0; i < cs.size(); ++i) {
        for (std::size_t j = 0; j < cs.size(); ++j) {
          bool linked = cs[i].first == cs[j].first;
          for (std::uint32_t a : neighbours(cs[i])) {
            for (std::uint32_t b : neighbours(cs[j])) linked |= a == b && a != v;
          }
          if (linked && group[j] < group[i]) {
            group[i] = group[j];
            changed = true;
          }
        }
      }
    }
    if (std::any_of(group.begin(), group.end(), [](std::size_t g) { return g != 0; })) {
      ++s.nonmanifold_vertices;
    }
  }
  s.euler = static_cast<std::int64_t>(s.vertices) - static_cast<std::int64_t>(s.edges) +
            static_cast<std::int64_t>(s.faces);
  s.closed = s.boundary_edges == 0 && s.nonmanifold_edges == 0;
  s.watertight = s.boundary_edges == s.border_boundary_edges && s.nonmanifold_edges == 0;
  return s;
}

void expect_same(const TopologyStats& got, const TopologyStats& want) {
  EXPECT_EQ(got.vertices, want.vertices);
  EXPECT_EQ(got.unreferenced_vertices, want.unreferenced_vertices);
  EXPECT_EQ(got.edges, want.edges);
  EXPECT_EQ(got.faces, want.faces);
  EXPECT_EQ(got.boundary_edges, want.boundary_edges);
  EXPECT_EQ(got.border_boundary_edges, want.border_boundary_edges);
  EXPECT_EQ(got.nonmanifold_edges, want.nonmanifold_edges);
  EXPECT_EQ(got.nonmanifold_vertices, want.nonmanifold_vertices);
  EXPECT_EQ(got.inconsistently_oriented_edges, want.inconsistently_oriented_edges);
  EXPECT_EQ(got.components, want.components);
  EXPECT_EQ(got.euler, want.euler);
  EXPECT_EQ(got.closed, want.closed);
  EXPECT_EQ(got.watertight, want.watertight);
}

// A random mesh for the reference comparisons: a dense soup (much non-manifoldness, faces that
// repeat a vertex) or a damaged torus (flipped and missing faces, unreferenced vertices), its
// vertices on the points of a 3x3x3 grid so that some boundary edges lie on the faces of the box
// [0, 2]^3.
Mesh random_mesh(std::mt19937& rng, int trial) {
  Mesh m;
  if (trial % 2 == 0) {
    const std::uint32_t nv = 3 + rng() % 30;
    m.positions.resize(nv);
    auto v = [&] { return static_cast<std::uint32_t>(rng() % nv); };
    for (std::uint32_t i = rng() % 40; i > 0; --i) m.triangles.push_back({v(), v(), v()});
    for (std::uint32_t i = rng() % 10; i > 0; --i) m.quads.push_back({v(), v(), v(), v()});
  } else {
    m = torus(3 + rng() % 6, 3 + rng() % 6, rng() % 2 == 0);
    for (auto& t : m.triangles) {
      if (rng() % 8 == 0) std::swap(t[0], t[1]);
    }
    for (auto& q : m.quads) {
      if (rng() % 8 == 0) std::swap(q[0], q[2]);
    }
    if (!m.triangles.empty()) m.triangles.erase(m.triangles.begin() + rng() % m.triangles.size());
    if (!m.quads.empty()) m.quads.erase(m.quads.begin() + rng() % m.quads.size());
    m.positions.resize(m.positions.size() + rng() % 3);
  }
  for (Vec3f& p : m.positions) {
    p = {float(rng() % 3), float(rng() % 3), float(rng() % 3)};
  }
  if (trial % 3 == 0) {
    std::shuffle(m.triangles.begin(), m.triangles.end(), rng);
    std::shuffle(m.quads.begin(), m.quads.end(), rng);
  }
  return m;
}

TEST(MeshTopology, MatchesReferenceOnRandomMeshes) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 200; ++trial) {
    SCOPED_TRACE(trial);
    const Mesh m = random_mesh(rng, trial);
    expect_same(mesh_topology(m), reference(m));
  }
}

TEST(MeshTopology, DeterministicAcrossThreadCounts) {
  std::mt19937 rng(5);
  Mesh m;
  m.positions.resize(5000);
  auto v = [&] { return static_cast<std::uint32_t>(rng() % 5000); };
  for (int i = 0; i < 40000; ++i) m.triangles.push_back({v(), v(), v()});
  for (int i = 0; i < 5000; ++i) m.quads.push_back({v(), v(), v(), v()});
  TopologyStats one, many;
  tbb::task_arena(1).execute([&] { one = mesh_topology(m); });
  many = mesh_topology(m);  // all available threads
  expect_same(many, one);
}

TEST(MeshTopology, MatchesReferenceInSmallChunks) {
  // Chunks of a few faces leave most vertices with faces in several chunks: the pass over such
  // shared vertices, the components linked across chunks, and the fast and the general
  // examination of a vertex all run, on meshes with every kind of defect.
  std::mt19937 rng(23);
  const std::array<Vec3f, 2> box{Vec3f{0, 0, 0}, Vec3f{2, 2, 2}};
  for (int trial = 0; trial < 150; ++trial) {
    SCOPED_TRACE(trial);
    const Mesh m = random_mesh(rng, trial);
    const TopologyStats want = reference(m, box);
    for (std::size_t chunk : {1, 2, 5, 0}) {
      SCOPED_TRACE(chunk);
      TopologyOptions options;
      options.border_box = box;
      options.chunk_faces = chunk;
      expect_same(mesh_topology(m, options), want);
    }
  }
}

// n triangles around vertex 0, wound alike; `closed`: the last one meets the first one.
Mesh fan(std::uint32_t n, bool closed) {
  Mesh m;
  const std::uint32_t rim = closed ? n : n + 1;
  m.positions.push_back({0, 0, 1});
  for (std::uint32_t i = 0; i < rim; ++i) {
    const double a = 2 * M_PI * i / (rim + (closed ? 0 : 1));
    m.positions.push_back({float(std::cos(a)), float(std::sin(a)), 0});
  }
  for (std::uint32_t i = 0; i < n; ++i) m.triangles.push_back({0, 1 + i, 1 + (i + 1) % rim});
  return m;
}

// Appends `part`'s vertices and faces to m.
void append(Mesh& m, const Mesh& part, bool share_vertex_0) {
  const auto offset = static_cast<std::uint32_t>(m.positions.size());
  auto map = [&](std::uint32_t v) { return share_vertex_0 && v == 0 ? 0 : v + offset; };
  m.positions.insert(m.positions.end(), part.positions.begin(), part.positions.end());
  for (const Tri& t : part.triangles) m.triangles.push_back({map(t[0]), map(t[1]), map(t[2])});
}

TEST(MeshTopology, FansOfEveryDegree) {
  // Around the centre up to 16 faces take the fast path, more the general one; both must agree
  // with the counts worked out by hand.
  for (std::uint32_t n : {1u, 2u, 3u, 15u, 16u, 17u, 40u}) {
    for (bool closed : {false, true}) {
      if (closed && n < 3) continue;
      SCOPED_TRACE(std::to_string(n) + (closed ? " closed" : " open"));
      const Mesh m = fan(n, closed);
      for (std::size_t chunk : {0, 1}) {
        TopologyOptions options;
        options.chunk_faces = chunk;
        const TopologyStats s = mesh_topology(m, options);
        EXPECT_EQ(s.vertices, closed ? n + 1 : n + 2);
        EXPECT_EQ(s.edges, closed ? 2 * n : 2 * n + 1);
        EXPECT_EQ(s.boundary_edges, closed ? n : n + 2);
        EXPECT_EQ(s.euler, 1);
        EXPECT_EQ(s.nonmanifold_vertices, 0u);
        EXPECT_EQ(s.nonmanifold_edges, 0u);
        EXPECT_EQ(s.inconsistently_oriented_edges, 0u);
        EXPECT_EQ(s.components, 1u);
        expect_same(s, reference(m));
      }
    }
  }
}

TEST(MeshTopology, SeveralFansAtOneVertex) {
  // Vertex 0 is the centre of each part. A closed fan and an open one (a cycle and a chain of
  // faces), two closed ones (two cycles: equal counts of faces and of links between them, like a
  // single closed fan), two open ones, and the same past the fast path's degree.
  struct Case {
    std::uint32_t a;
    bool a_closed;
    std::uint32_t b;
    bool b_closed;
  };
  for (const Case c : {Case{6, true, 1, false}, Case{5, true, 4, true}, Case{3, false, 2, false},
                       Case{8, true, 8, true}, Case{12, true, 9, false}}) {
    SCOPED_TRACE(std::to_string(c.a) + " " + std::to_string(c.b));
    Mesh m = fan(c.a, c.a_closed);
    append(m, fan(c.b, c.b_closed), true);
    for (std::size_t chunk : {0, 1, 4}) {
      TopologyOptions options;
      options.chunk_faces = chunk;
      const TopologyStats s = mesh_topology(m, options);
      EXPECT_EQ(s.nonmanifold_vertices, 1u);
      EXPECT_EQ(s.nonmanifold_edges, 0u);
      EXPECT_EQ(s.components, 1u);
      expect_same(s, reference(m));
    }
  }
}

TEST(MeshTopology, SameForAnyChunkSizeAndThreadCount) {
  // A larger damaged surface: two tori, one with flipped and missing faces, fans glued on, and
  // three faces on one of its edges, faces interleaved in memory so that chunks mix them.
  Mesh m = torus(60, 40, false);
  for (std::size_t t = 0; t < m.triangles.size(); t += 37)
    std::swap(m.triangles[t][0], m.triangles[t][1]);
  for (std::size_t t = 0; t < m.triangles.size(); t += 101) m.triangles[t] = {0, 0, 0};
  append(m, torus(20, 10, false), false);
  append(m, fan(7, true), true);
  append(m, fan(5, false), false);
  m.triangles.push_back({m.triangles[500][1], m.triangles[500][0], 2});
  m.positions.resize(m.positions.size() + 2);
  std::mt19937 rng(3);
  std::shuffle(m.triangles.begin() + m.triangles.size() / 2, m.triangles.end(), rng);
  const TopologyStats want = reference(m);
  EXPECT_GT(want.nonmanifold_vertices, 0u);
  EXPECT_GT(want.nonmanifold_edges, 0u);
  EXPECT_GT(want.inconsistently_oriented_edges, 0u);
  EXPECT_GT(want.boundary_edges, 0u);
  EXPECT_GE(want.unreferenced_vertices, 2u);
  for (int threads : {1, 2, 3}) {
    for (std::size_t chunk : {1, 3, 64, 1000, 0}) {
      SCOPED_TRACE(std::to_string(threads) + " threads, chunks of " + std::to_string(chunk));
      TopologyOptions options;
      options.chunk_faces = chunk;
      TopologyStats got;
      tbb::task_arena(threads).execute([&] { got = mesh_topology(m, options); });
      expect_same(got, want);
    }
  }
}

}  // namespace
}  // namespace isotile
