// Helpers shared by the extractor test suites.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume.h"
#include "skip_support.h"

namespace isotile::testing {

// A real volume from ../shared/data (may not exist: callers skip with ISOTILE_SKIP).
inline std::filesystem::path shared_volume(const char* name) {
  return std::filesystem::path(ISOTILE_SHARED_DATA) / name;
}

// Skips (or, where demanded, fails) the current test unless the shared volume exists.
#define ISOTILE_REQUIRE_SHARED(path)                                     \
  do {                                                                   \
    if (!std::filesystem::exists(path))                                  \
      ISOTILE_SKIP(SharedData, "no shared data at " << (path).string()); \
  } while (0)

// The edges with `faces` faces (1: the boundary; 3 or more: non-manifold, with faces = 0) as
// sorted position pairs: where they run, whatever the vertex indices.
inline std::set<std::array<float, 6>> edges_by_faces(const Mesh& m, int faces) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> count;
  for (const Tri& t : m.triangles)
    for (int i = 0; i < 3; ++i) ++count[std::minmax(t[i], t[(i + 1) % 3])];
  std::set<std::array<float, 6>> out;
  for (const auto& [e, c] : count) {
    if (faces == 0 ? c <= 2 : c != faces) continue;
    Vec3f a = m.positions[e.first], b = m.positions[e.second];
    if (b < a) std::swap(a, b);
    out.insert({a[0], a[1], a[2], b[0], b[1], b[2]});
  }
  return out;
}
inline std::set<std::array<float, 6>> boundary_edges(const Mesh& m) {
  return edges_by_faces(m, 1);
}
inline std::set<std::array<float, 6>> nonmanifold_edges(const Mesh& m) {
  return edges_by_faces(m, 0);
}

// A fresh folder per test (named after the suite's `prefix` and the test), removed afterwards.
class TempDirTest : public ::testing::Test {
 protected:
  explicit TempDirTest(const char* prefix) : prefix_(prefix) {}
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           (prefix_ + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  static std::string slurp(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

  std::string prefix_;
  std::filesystem::path dir_;
};

// Largest distance, in voxels, from a vertex of `m` to the field's exact surface.
// An empty mesh is no answer: it fails the test (and reads as infinitely far), so an extractor
// that returns nothing cannot pass a bound on its error.
inline double max_distance(const FieldSpec& spec, const Mesh& m) {
  if (m.positions.empty() || (m.triangles.empty() && m.quads.empty())) {
    ADD_FAILURE() << "an empty mesh where a surface was expected";
    return INFINITY;
  }
  double worst = 0;
  for (const Vec3f& p : m.positions)
    worst = std::max(worst, distance_voxels(spec, {p[0], p[1], p[2]}));
  return worst;
}

// Every run is byte-identical to the first (positions, normals, triangles, quads): the
// determinism contract across thread counts.
inline void expect_identical_runs(const std::vector<Mesh>& runs) {
  for (std::size_t i = 1; i < runs.size(); ++i) {
    EXPECT_EQ(runs[i].positions, runs[0].positions) << "run " << i;
    EXPECT_EQ(runs[i].normals, runs[0].normals) << "run " << i;
    EXPECT_EQ(runs[i].triangles, runs[0].triangles) << "run " << i;
    EXPECT_EQ(runs[i].quads, runs[0].quads) << "run " << i;
  }
}

// An extraction of `cells` (global cell box; empty = all) from `view`, with the keys of its
// vertices.
struct KeyedMesh {
  Mesh mesh;
  std::vector<std::uint64_t> keys;
};
using KeyedExtract = std::function<KeyedMesh(const VolumeView& view, const Box3& cells)>;

// Cuts the cells of `whole` into bricks of `brick` cells (the last ones shorter), extracts each
// from a view holding it plus `halo` samples, and checks the brick contract: every vertex a brick
// lists exists in the whole-volume mesh under the same key with bit-identical position and normal,
// and the bricks' faces, mapped through the keys, are exactly the whole mesh's faces.
inline void expect_bricks_equal_whole(const VolumeView& whole, const KeyedExtract& extract,
                                      int halo, const Index3& brick) {
  const KeyedMesh ref = extract(whole, Box3{});
  ASSERT_TRUE(std::is_sorted(ref.keys.begin(), ref.keys.end()));
  ASSERT_EQ(ref.keys.size(), ref.mesh.positions.size());
  std::vector<std::array<std::uint32_t, 4>> want, got;
  auto add = [](std::vector<std::array<std::uint32_t, 4>>& out, const Mesh& m, auto&& map) {
    for (const Tri& t : m.triangles) out.push_back({map(t[0]), map(t[1]), map(t[2]), ~0u});
    for (const Quad& q : m.quads) out.push_back({map(q[0]), map(q[1]), map(q[2]), map(q[3])});
  };
  add(want, ref.mesh, [](std::uint32_t i) { return i; });
  Index3 cells;
  for (int a = 0; a < 3; ++a) cells[a] = whole.dims[a] - 1;
  for (std::int64_t z = 0; z < cells[2]; z += brick[2])
    for (std::int64_t y = 0; y < cells[1]; y += brick[1])
      for (std::int64_t x = 0; x < cells[0]; x += brick[0]) {
        Box3 box{{x, y, z},
                 {std::min(x + brick[0], cells[0]), std::min(y + brick[1], cells[1]),
                  std::min(z + brick[2], cells[2])}};
        Box3 local;
        for (int a = 0; a < 3; ++a) {
          local.lo[a] = std::max<std::int64_t>(box.lo[a] - halo, 0);
          local.hi[a] = std::min<std::int64_t>(box.hi[a] + halo + 1, whole.dims[a]);
        }
        // A copy, not a window into `whole`: a read beyond the view (a halo too small) then
        // sees other samples, or trips the sanitizers, instead of the right neighbours.
        const VolumeView part = subview(whole, local);
        const std::size_t size = scalar_size(part.type);
        std::vector<std::byte> copy(static_cast<std::size_t>(part.sample_count()) * size);
        for (std::int64_t k = 0; k < part.dims[2]; ++k)
          for (std::int64_t j = 0; j < part.dims[1]; ++j)
            for (std::int64_t i = 0; i < part.dims[0]; ++i)
              std::memcpy(
                  copy.data() +
                      static_cast<std::size_t>(i + part.dims[0] * (j + part.dims[1] * k)) * size,
                  static_cast<const std::byte*>(part.data) + part.offset(i, j, k) * size, size);
        VolumeView own = part;
        own.data = copy.data();
        own.strides = {1, part.dims[0], part.dims[0] * part.dims[1]};
        const KeyedMesh b = extract(own, box);
        ASSERT_EQ(b.keys.size(), b.mesh.positions.size());
        ASSERT_TRUE(std::is_sorted(b.keys.begin(), b.keys.end()));
        std::vector<std::uint32_t> to_whole(b.keys.size());
        for (std::size_t i = 0; i < b.keys.size(); ++i) {
          const auto it = std::lower_bound(ref.keys.begin(), ref.keys.end(), b.keys[i]);
          ASSERT_TRUE(it != ref.keys.end() && *it == b.keys[i]) << "key " << b.keys[i];
          const auto w = static_cast<std::uint32_t>(it - ref.keys.begin());
          to_whole[i] = w;
          ASSERT_EQ(b.mesh.positions[i], ref.mesh.positions[w]) << "key " << b.keys[i];
          if (!ref.mesh.normals.empty()) {
            ASSERT_EQ(b.mesh.normals[i], ref.mesh.normals[w]) << "key " << b.keys[i];
          }
        }
        add(got, b.mesh, [&](std::uint32_t i) { return to_whole[i]; });
      }
  std::sort(want.begin(), want.end());
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, want);
}

// Labels 0, 1, 2 at random, x fastest (a label map at iso 1: ties everywhere, most with a free
// side, many moved along the level set by Macet; isovalue_ties.h).
inline std::vector<std::uint8_t> random_labels(const Index3& n, unsigned seed) {
  std::vector<std::uint8_t> samples(static_cast<std::size_t>(n[0] * n[1] * n[2]));
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> u(0, 2);
  for (std::uint8_t& s : samples) s = static_cast<std::uint8_t>(u(rng));
  return samples;
}

}  // namespace isotile::testing
