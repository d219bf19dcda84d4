#include "tiler/tiled_simplify.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/errors.h"
#include "core/mesh/atomic_file.h"
#include "tiler/brick_reader.h"
#include "tiler/source_histogram.h"

namespace isotile {

namespace {

Vec3f to_float(const Vec3d& p) {
  return {static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2])};
}

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// Simplification's working set per face of a piece (OpenMesh's mesh, the heap, quadrics, the
// copies between passes) as resident memory, the allocator's holes included; a brick also holds
// its extraction (counted apart). Measured per brick, the heap trimmed (malloc_trim) and the
// peak RSS reset before each (bonsai tiled 4x4, MC and DC, --memory 64MiB; bonsai at 16 MiB;
// gyroid 200 at 8 MiB, every method): up to 707 bytes a face for bricks near the budget, median
// 550. At 450 (from `isotile simplify` of bonsai's Macet mesh: 350 above reading it), bonsai
// tiled 4x4 at 64 MiB had bricks at up to 1.47 times their estimates (with slices then planned
// as even shares of a brick's faces).
constexpr double kSimplifyBytesPerFace = 720;
// A seam cell also holds its octants as read, the piece built from them and the piece handed
// back, and its reduction is milder (more faces survive per face read): per face of cells near
// the budget, measured as above, up to 1005 bytes (median 880; smaller cells up to 1330, their
// fixed costs spread over fewer faces). At 800, up to 1.37 times their estimates.
constexpr double kSeamBytesPerFace = 1050;

// A file for intermediate data, unlinked from the start: it vanishes however the process ends.
// Scratch files go beside the output (its file system has room for the mesh), or, where the
// output is written in place (a device, a FIFO, standard output), to the temporary folder
// (TMPDIR): not into /dev or /proc.
std::filesystem::path scratch_folder(const std::filesystem::path& output) {
  const OutputTarget t = resolve_output(output);
  if (!t.in_place()) return t.path.parent_path();
  std::error_code ec;
  const std::filesystem::path dir = std::filesystem::temp_directory_path(ec);
  if (ec) {
    const char* env = std::getenv("TMPDIR");
    throw IoError("cannot keep scratch files for " + output.string() +
                  " (written in place, so not beside it): the temporary folder" +
                  (env ? std::string(" TMPDIR=") + env : std::string(" /tmp")) + ": " +
                  ec.message());
  }
  return dir;
}

class ScratchFile {
 public:
  explicit ScratchFile(const std::filesystem::path& dir) {
    const std::string d = dir.empty() ? "." : dir.string();
    fd_ = ::open(d.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (fd_ < 0) {  // file systems without O_TMPFILE: create, then unlink at once
      std::string name = d + "/.isotile-scratch-XXXXXX";
      fd_ = ::mkstemp(name.data());
      if (fd_ >= 0) ::unlink(name.c_str());
    }
    if (fd_ < 0)
      throw IoError("cannot create a scratch file in " + d + ": " + std::strerror(errno));
    dir_ = d;
  }
  ~ScratchFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;

  std::uint64_t size() const { return size_; }
  void append(const void* data, std::size_t n) { write_at(size_, data, n); }
  // Anywhere, past the end too (the gap reads as zeros until written).
  void write_at(std::uint64_t offset, const void* data, std::size_t n) {
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
      const ssize_t w = ::pwrite(fd_, p, n, static_cast<off_t>(offset));
      if (w <= 0) {
        if (w < 0 && errno == EINTR) continue;
        // In the output's folder, or the temporary one where the output is written in place.
        throw IoError("cannot write a scratch file in " + dir_ + ": " + std::strerror(errno));
      }
      p += w;
      n -= static_cast<std::size_t>(w);
      offset += static_cast<std::uint64_t>(w);
      size_ = std::max(size_, offset);
    }
  }
  void read(std::uint64_t offset, void* out, std::size_t n) const {
    char* p = static_cast<char*>(out);
    while (n > 0) {
      const ssize_t r = ::pread(fd_, p, n, static_cast<off_t>(offset));
      if (r <= 0) {
        if (r < 0 && errno == EINTR) continue;
        throw IoError(std::string("cannot read back a scratch file: ") +
                      (r == 0 ? "it is shorter than written" : std::strerror(errno)));
      }
      p += r;
      n -= static_cast<std::size_t>(r);
      offset += static_cast<std::uint64_t>(r);
    }
  }

 private:
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::string dir_;  // where it was made, for messages
};

// One octant of one simplified brick (or slice) in the spill file: its vertices (with keys and
// quadrics) and its faces in chunk-local indices.
struct SpillVertex {
  std::uint64_t key;
  Vec3d position;
  Quadric quadric;
};
struct Chunk {
  std::uint64_t offset = 0;
  std::uint32_t vertices = 0, faces = 0;
  // Faces by the grid z-cell of their centroid (face_z_cell), from z0: what the seam pass needs
  // to cut a cell the budget cannot hold into z-parts without reading it first.
  std::int64_t z0 = 0;
  std::vector<std::uint32_t> z_faces;
};

template <class T>
char* put_le(char* p, T v) {
  static_assert(std::endian::native == std::endian::little, "little-endian hosts only");
  std::memcpy(p, &v, sizeof(T));
  return p + sizeof(T);
}

// The vertices of a piece that lie on its boundary (an edge with one face): the ones it may
// share with other pieces.
std::vector<char> boundary_vertices(const MeshPiece& p) {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  edges.reserve(3 * p.triangles.size());
  for (const Tri& t : p.triangles)
    for (int i = 0; i < 3; ++i) edges.emplace_back(std::minmax(t[i], t[(i + 1) % 3]));
  std::sort(edges.begin(), edges.end());
  std::vector<char> on(p.positions.size(), 0);
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i + 1;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) on[edges[i].first] = on[edges[i].second] = 1;
    i = j;
  }
  return on;
}

class TiledSimplification {
 public:
  TiledSimplification(VolumeSource& source, const TiledOptions& options,
                      const std::filesystem::path& output)
      : src_(source),
        opt_(options),
        n_(source.dims),
        reader_(source, options.extract),
        dir_(scratch_folder(output)),
        chunks_spill_(dir_),
        vertices_(dir_),
        faces_(dir_),
        shared_spill_(dir_) {
    if (options.format != MeshFormat::Ply && options.format != MeshFormat::Stl)
      throw InputError("streamed (--memory) output is binary PLY or STL");
    if (!(options.simplify > 0)) throw InputError("the simplification ratio must be in (0, 1]");
    if (options.extract.method == Method::DualContouring && options.extract.keep_quads)
      throw InputError("simplification gives triangles; drop --quads");
    normals_ = options.extract.normals;
    sopt_.ratio = options.simplify;
    sopt_.min_quality = options.simplify_min_quality;
  }

  TiledResult run(const std::filesystem::path& output) {
    TiledResult result;
    for (int a = 0; a < 3; ++a)
      if (n_[a] < 2) {  // no cells, so no face
        if (!opt_.allow_empty) {
          throw_no_surface(src_, opt_.memory, opt_.extract.iso);
        }
        write_mesh(Mesh{}, output, {.format = opt_.format, .ascii = false});
        return result;
      }
    // 1. Count, to know each brick's size before extracting it. Simplifying a brick needs far
    // more memory per face than extracting it, and faces per cell vary from volume to volume:
    // plan once, count, and plan again with the densest z-plane's faces per cell (what a slab
    // of a gzip'd source must hold), counting again if the bricks changed.
    auto t0 = Clock::now();
    BrickPlanOptions po = reader_.plan_options(opt_.memory, opt_.max_read_amplification);
    // A budget too small even to extract is counted within the least that extracts, so that the
    // refusal below names what simplifying needs: refused at once, it named the extraction's
    // need, and a run given that was refused again with more.
    try {
      plan_ = plan_bricks(n_, po);
    } catch (const InputError&) {
      BrickPlanOptions least = po;
      least.memory = least_memory(n_, po);
      plan_ = plan_bricks(n_, least);
    }
    std::vector<std::uint64_t> brick_vertices, brick_faces, plane_faces;
    std::vector<std::vector<std::uint64_t>> brick_planes;
    count(brick_vertices, brick_faces, plane_faces, brick_planes);
    const double plane_cells = static_cast<double>(n_[0] - 1) * static_cast<double>(n_[1] - 1);
    const double densest =
        static_cast<double>(*std::max_element(plane_faces.begin(), plane_faces.end())) /
        plane_cells;
    po.output_bytes_per_cell += densest * kSimplifyBytesPerFace;
    // Throws where po.memory is too small for simplifying (always where it was for extracting:
    // more bytes per cell), naming the budget that plans.
    const BrickPlan replanned = plan_bricks(n_, po);
    if (replanned.brick != plan_.brick) {
      plan_ = replanned;
      count(brick_vertices, brick_faces, plane_faces, brick_planes);
    }
    if (!opt_.allow_empty && std::all_of(brick_faces.begin(), brick_faces.end(),
                                         [](std::uint64_t n) { return n == 0; })) {
      throw_no_surface(src_, opt_.memory, opt_.extract.iso);
    }
    result.plan = plan_;
    result.backend = reader_.extract().backend;
    const std::int64_t bricks = plan_.total();
    result.seconds_count = since(t0);

    // An even count would cut at the brick's middle plane, which is also a seam cell's boundary:
    // that cut would stay locked in both passes.
    const std::vector<BrickReader::Slicing> cuts = slice_bricks(
        bricks,
        [&](std::int64_t b) {
          return reader_.slice(plan_.cells(b), brick_vertices[b], brick_planes[b], opt_.memory,
                               kSimplifyBytesPerFace, true);
        },
        opt_.memory, opt_.warn);

    // 2. Extract and simplify each brick; spill its octants.
    t0 = Clock::now();
    chunks_.assign(static_cast<std::size_t>(bricks) * 8, {});
    src_.rewind();
    for (std::int64_t b = 0; b < bricks; ++b) {
      const Box3 cells = plan_.cells(b);
      const BrickReader::Slicing& cut = cuts[static_cast<std::size_t>(b)];
      const std::int64_t slices = cut.count;
      for (std::int64_t s = 0; s < slices; ++s) {
        simplify_brick(b, z_slice(cells, s, slices), result, bricks);
        ++result.bricks_extracted;
      }
      result.largest_brick_bytes = std::max(result.largest_brick_bytes, cut.bytes);
      if (opt_.progress) Progress(*opt_.progress, Stage::Simplify, b, bricks).finish();
    }
    result.seconds_extract = since(t0);

    // 3. The seams: cells of the grid shifted by half a brick.
    t0 = Clock::now();
    const std::uint64_t target = std::max<std::uint64_t>(
        1, static_cast<std::uint64_t>(
               std::llround(opt_.simplify * static_cast<double>(result.triangles_extracted))));
    plan_seams(result);
    const std::int64_t cells = result.seam_cells[0] * result.seam_cells[1] * result.seam_cells[2];
    keep_ = spilled_faces_ > 0
                ? std::min(1.0, static_cast<double>(target) / static_cast<double>(spilled_faces_))
                : 1.0;
    if (opt_.progress) opt_.progress->set_brick(0, 1);
    progress_begin(opt_.progress, Stage::SimplifySeams, cells);
    plan_units();
    for (std::int64_t c = 0; c < cells; ++c) {
      const std::vector<std::int64_t>& cuts = cell_parts_[static_cast<std::size_t>(c)];
      for (std::size_t i = 0; i <= cuts.size(); ++i) {
        seam_cell(c, i == 0 ? std::numeric_limits<std::int64_t>::min() : cuts[i - 1],
                  i < cuts.size() ? cuts[i] : std::numeric_limits<std::int64_t>::max(), result);
        retire(unit_);
        ++unit_;
      }
      progress_advance(opt_.progress);
    }
    result.seconds_seams = since(t0);

    result.simplify.target_faces = target;
    result.simplify.faces_before = result.triangles_extracted;
    result.simplify.faces_after = result.triangles;
    // Said before the file is written (a front end may make it an error).
    if (const std::string missed = target_missed(result.simplify); !missed.empty())
      say_warning(opt_.warn, result.triangles > target
                                 ? missed +
                                       " (each brick's border is locked until the seams' pass: "
                                       "larger bricks, a larger --memory, lock fewer vertices)"
                                 : missed);

    // 4. The file, once the input is known to have stayed as it was read.
    src_.check_unchanged();
    assemble(output, result);
    result.quality = quality_.stats();
    return result;
  }

 private:
  // Vertices and faces of every brick of the plan, and faces per z-plane of cells, over the
  // volume and within each brick.
  void count(std::vector<std::uint64_t>& vertices, std::vector<std::uint64_t>& faces,
             std::vector<std::uint64_t>& plane_faces,
             std::vector<std::vector<std::uint64_t>>& brick_planes) {
    const std::int64_t bricks = plan_.total();
    vertices.assign(static_cast<std::size_t>(bricks), 0);
    faces.assign(static_cast<std::size_t>(bricks), 0);
    plane_faces.assign(static_cast<std::size_t>(n_[2] - 1), 0);
    brick_planes.assign(static_cast<std::size_t>(bricks), {});
    const std::uint64_t mult = reader_.extract().method == Method::DualContouring ? 2 : 1;
    src_.rewind();
    for (std::int64_t b = 0; b < bricks; ++b) {
      const Box3 cells = plan_.cells(b);
      const BrickCounts c = reader_.count(cells);
      for (std::uint32_t x : c.vertices.count) vertices[b] += x;
      std::vector<std::uint64_t>& planes = brick_planes[static_cast<std::size_t>(b)];
      planes.assign(static_cast<std::size_t>(cells.extent(2)), 0);
      const std::int64_t ny = c.faces.box.extent(1);
      for (std::size_t r = 0; r < c.faces.count.size(); ++r) {
        const std::int64_t z = c.faces.box.lo[2] + static_cast<std::int64_t>(r) / ny;
        const std::uint64_t n = c.faces.count[r] * mult;
        faces[b] += n;
        plane_faces[static_cast<std::size_t>(std::min(z, n_[2] - 2))] += n;
        // The volume's last sample plane (a last brick's, for sample-owned faces) has no cells
        // above: its faces go with the plane below.
        planes[static_cast<std::size_t>(std::min(z, cells.hi[2] - 1) - cells.lo[2])] += n;
      }
      if (opt_.progress) {
        opt_.progress->set_brick(b, bricks);
        opt_.progress->begin(Stage::Count, 1);
        opt_.progress->advance();
      }
    }
  }

  // Index coordinates of a world position (the grid's, where bricks are boxes of cells).
  double grid_coord(const Vec3d& p, int a) const {
    return (p[a] - src_.origin[a]) / src_.spacing[a];
  }

  // The grid z-cell a face's centroid lies in: which z-part of a seam cell the face goes to.
  std::int64_t face_z_cell(const Vec3d& a, const Vec3d& b, const Vec3d& c) const {
    return static_cast<std::int64_t>(
        std::floor((grid_coord(a, 2) + grid_coord(b, 2) + grid_coord(c, 2)) / 3));
  }

  void simplify_brick(std::int64_t b, const Box3& part, TiledResult& result, std::int64_t bricks) {
    // The extraction and the simplification report within the brick (core/progress.h).
    ChildProgress child(opt_.progress, Stage::Simplify, b, bricks);
    const VolumeView view = reader_.read(grow(part, reader_.halo(), n_));
    ExtractOptions o = reader_.extract();
    o.cells = part;
    o.progress = child.get();
    o.normals = false;  // the simplified mesh gets area-weighted normals
    BackendChoice ran;
    Mesh mesh = extract(view, o, &ran);
    if (ran.gpu) accumulate_gpu_report(result.gpu, *ran.gpu);
    std::vector<std::uint64_t> keys = brick_vertex_keys(view, o.iso, reader_.layout(), part);
    if (keys.size() != mesh.positions.size())
      throw Error("brick contract broken: the extractor listed " +
                  std::to_string(mesh.positions.size()) + " vertices where " +
                  std::to_string(keys.size()) + " were expected");
    MeshPiece piece;
    piece.keys = std::move(keys);
    piece.positions.reserve(mesh.positions.size());
    for (const Vec3f& p : mesh.positions) piece.positions.push_back({p[0], p[1], p[2]});
    piece.triangles = std::move(mesh.triangles);
    result.triangles_extracted += piece.triangles.size();
    const auto target = static_cast<std::uint64_t>(
        std::llround(opt_.simplify * static_cast<double>(piece.triangles.size())));
    SimplifyOptions so = sopt_;
    so.progress = child.get();
    const MeshPiece out = simplify_piece(std::move(piece), std::max<std::uint64_t>(target, 1), so,
                                         &result.simplify, /*boundary_allowance=*/true);
    spill(b, out);
  }

  // Cuts a simplified brick into its octants (by face centroid against the brick's middle
  // planes) and appends each to the spill file.
  void spill(std::int64_t b, const MeshPiece& p) {
    const Box3 cells = plan_.cells(b);
    std::vector<std::uint8_t> octant(p.triangles.size());
    for (std::size_t f = 0; f < p.triangles.size(); ++f) {
      int o = 0;
      for (int a = 0; a < 3; ++a) {
        double c = 0;
        for (std::uint32_t v : p.triangles[f]) c += grid_coord(p.positions[v], a) / 3;
        if (c >= 0.5 * static_cast<double>(cells.lo[a] + cells.hi[a])) o |= 1 << a;
        // How far a face's centroid, which places it, lies from its vertices: how far from a
        // vertex the seam pass may still meet it.
        for (std::uint32_t v : p.triangles[f])
          reach_ = std::max(reach_, std::abs(c - grid_coord(p.positions[v], a)));
      }
      octant[f] = static_cast<std::uint8_t>(o);
    }
    std::vector<std::int64_t> local(p.positions.size());
    std::vector<SpillVertex> vs;
    std::vector<Tri> fs;
    for (int o = 0; o < 8; ++o) {
      std::fill(local.begin(), local.end(), -1);
      vs.clear();
      fs.clear();
      for (std::size_t f = 0; f < p.triangles.size(); ++f) {
        if (octant[f] != o) continue;
        Tri t;
        for (int i = 0; i < 3; ++i) {
          const std::uint32_t v = p.triangles[f][i];
          if (local[v] < 0) {
            local[v] = static_cast<std::int64_t>(vs.size());
            vs.push_back({p.keys[v], p.positions[v], p.quadrics[v]});
          }
          t[i] = static_cast<std::uint32_t>(local[v]);
        }
        fs.push_back(t);
      }
      if (fs.empty()) continue;
      Chunk c;
      c.offset = chunks_spill_.size();
      c.vertices = static_cast<std::uint32_t>(vs.size());
      c.faces = static_cast<std::uint32_t>(fs.size());
      std::vector<std::int64_t> z(fs.size());
      for (std::size_t f = 0; f < fs.size(); ++f)
        z[f] = face_z_cell(vs[fs[f][0]].position, vs[fs[f][1]].position, vs[fs[f][2]].position);
      c.z0 = *std::min_element(z.begin(), z.end());
      c.z_faces.assign(static_cast<std::size_t>(*std::max_element(z.begin(), z.end()) - c.z0 + 1),
                       0);
      for (std::int64_t zf : z) ++c.z_faces[static_cast<std::size_t>(zf - c.z0)];
      chunks_spill_.append(vs.data(), vs.size() * sizeof(SpillVertex));
      chunks_spill_.append(fs.data(), fs.size() * sizeof(Tri));
      chunks_[static_cast<std::size_t>(b) * 8 + o].push_back(c);
      spilled_faces_ += fs.size();
    }
  }

  // The seam cells. A cell's boundaries are middle planes of bricks (half-brick h of an axis is
  // the lower half of brick h / 2 when h is even), so every seam between two bricks lies inside
  // a cell: cell j along an axis grouping k bricks holds half-bricks 2kj - 1 to 2k(j + 1) - 2.
  // Starting from one brick per cell (the grid shifted by half a brick), cells grow, doubling
  // along the axis with the most of them, as long as the largest still fits the budget with the
  // faces the bricks left: fewer locked cell boundaries, fewer faces held back by them.
  void plan_seams(TiledResult& result) {
    Index3 k{1, 1, 1};
    const auto along = [&](int a, std::int64_t g) { return seam_cells_along(a, g); };
    auto largest = [&](const Index3& g) {
      std::unordered_map<std::int64_t, std::uint64_t> faces;
      for_each_octant(g, [&](std::int64_t cell, std::size_t slot) {
        for (const Chunk& ch : chunks_[slot]) faces[cell] += ch.faces;
      });
      std::uint64_t most = 0;
      for (const auto& [cell, f] : faces) most = std::max(most, f);
      return most;
    };
    const auto fits = [&](const Index3& g) {
      return static_cast<double>(largest(g)) * kSeamBytesPerFace <=
             static_cast<double>(opt_.memory);
    };
    for (bool grew = true; grew;) {
      grew = false;
      int axes[3] = {0, 1, 2};
      std::stable_sort(axes, axes + 3,
                       [&](int x, int y) { return along(x, k[x]) > along(y, k[y]); });
      for (int a : axes) {
        if (along(a, k[a]) == 1) continue;
        Index3 g = k;
        g[a] *= 2;
        if (fits(g)) {
          k = g;
          grew = true;
          break;
        }
      }
    }
    seam_group_ = k;
    for (int a = 0; a < 3; ++a) result.seam_cells[a] = along(a, k[a]);
    cell_slots_.assign(static_cast<std::size_t>(result.seam_cells[0] * result.seam_cells[1] *
                                                result.seam_cells[2]),
                       {});
    for_each_octant(k, [&](std::int64_t cell, std::size_t slot) {
      if (!chunks_[slot].empty()) cell_slots_[static_cast<std::size_t>(cell)].push_back(slot);
    });
    plan_seam_parts(result);
  }

  // A seam cell of one brick whose faces the budget cannot hold is cut into z-parts, by the
  // grid z-cell of each face's centroid: the parts' boundaries are locked in this pass, as the
  // cell's own are, but they run through the bricks' insides, which the first pass simplified
  // freely; the seam between the bricks stays inside a part (no cut on a brick's boundary
  // plane, and an odd count of equal parts puts the middle one round it). Before 2026-11-29
  // such cells were held whole: bonsai at 50, --simplify 0.5 --memory 8MiB ran seam cells of
  // 15.0 MB, 1.78 times the budget, without a word. Cells that fit stay whole (and the file
  // as it was).
  void plan_seam_parts(TiledResult& result) {
    const auto budget = static_cast<double>(opt_.memory);
    std::vector<std::int64_t> brick_planes;  // the bricks' z boundaries, not to be cut on
    for (std::int64_t bz = 1; bz < plan_.count[2]; ++bz)
      brick_planes.push_back(plan_.cells(bz * plan_.count[0] * plan_.count[1]).lo[2]);
    const auto on_brick_plane = [&](std::int64_t z) {
      return std::binary_search(brick_planes.begin(), brick_planes.end(), z);
    };
    std::uint64_t over = 0;
    cell_parts_.assign(cell_slots_.size(), {});
    for (std::size_t c = 0; c < cell_slots_.size(); ++c) {
      std::int64_t lo = std::numeric_limits<std::int64_t>::max();
      std::int64_t hi = std::numeric_limits<std::int64_t>::min();
      std::uint64_t faces = 0;
      for (std::size_t slot : cell_slots_[c])
        for (const Chunk& ch : chunks_[slot]) {
          faces += ch.faces;
          lo = std::min(lo, ch.z0);
          hi = std::max(hi, ch.z0 + static_cast<std::int64_t>(ch.z_faces.size()));
        }
      if (faces == 0 || static_cast<double>(faces) * kSeamBytesPerFace <= budget) continue;
      // Faces by z-cell over the cell, and their prefix sums.
      std::vector<std::uint64_t> prefix(static_cast<std::size_t>(hi - lo) + 1, 0);
      for (std::size_t slot : cell_slots_[c])
        for (const Chunk& ch : chunks_[slot])
          for (std::size_t i = 0; i < ch.z_faces.size(); ++i)
            prefix[static_cast<std::size_t>(ch.z0 - lo) + i + 1] += ch.z_faces[i];
      for (std::size_t i = 1; i < prefix.size(); ++i) prefix[i] += prefix[i - 1];
      const std::int64_t extent = hi - lo;
      std::vector<std::int64_t> best;
      std::uint64_t best_most = faces;
      for (std::int64_t parts = 3; parts <= extent; parts += 2) {
        std::vector<std::int64_t> cuts;
        for (std::int64_t i = 1; i < parts; ++i) {
          std::int64_t z = lo + extent * i / parts;
          if (on_brick_plane(z)) z += (z + 1 < hi ? 1 : -1);
          if (z > (cuts.empty() ? lo : cuts.back()) && z < hi && !on_brick_plane(z))
            cuts.push_back(z);
        }
        std::uint64_t most = 0;
        std::int64_t from = lo;
        for (std::size_t i = 0; i <= cuts.size(); ++i) {
          const std::int64_t to = i < cuts.size() ? cuts[i] : hi;
          most = std::max(most, prefix[static_cast<std::size_t>(to - lo)] -
                                    prefix[static_cast<std::size_t>(from - lo)]);
          from = to;
        }
        if (most < best_most) {
          best_most = most;
          best = cuts;
        }
        if (static_cast<double>(most) * kSeamBytesPerFace <= budget) break;
      }
      cell_parts_[c] = std::move(best);
      if (static_cast<double>(best_most) * kSeamBytesPerFace > budget)
        over = std::max(
            over, static_cast<std::uint64_t>(kSeamBytesPerFace * static_cast<double>(best_most)));
    }
    if (over > 0)
      say_warning(opt_.warn, "the memory budget of " + std::to_string(opt_.memory) +
                                 " bytes is too small for the seams' pass of the simplification: "
                                 "its densest seam cell needs " +
                                 std::to_string(over) +
                                 " bytes even cut into z-parts; the run goes over the budget");
    std::int64_t parts = 0;
    for (const auto& cuts : cell_parts_) parts += static_cast<std::int64_t>(cuts.size()) + 1;
    result.seam_parts = parts;
  }

  // Seam cells along axis a when a cell groups g bricks, and the one holding half-brick h (the
  // lower half of brick h / 2 when h is even).
  std::int64_t seam_cells_along(int a, std::int64_t g) const {
    return 2 * plan_.count[a] / (2 * g) + 1;
  }
  static std::int64_t seam_cell_of_half(std::int64_t h, std::int64_t g) {
    return (h + 1) / (2 * g);
  }

  // Calls f(cell, slot) for every octant slot (brick * 8 + octant) of the plan, with the seam
  // cell it falls in when cells group `g` bricks per axis.
  template <class F>
  void for_each_octant(const Index3& g, F&& f) const {
    Index3 cells;
    for (int a = 0; a < 3; ++a) cells[a] = seam_cells_along(a, g[a]);
    for (std::int64_t b = 0; b < plan_.total(); ++b) {
      const std::int64_t bi[3] = {b % plan_.count[0], b / plan_.count[0] % plan_.count[1],
                                  b / plan_.count[0] / plan_.count[1]};
      for (int o = 0; o < 8; ++o) {
        std::int64_t j[3];
        for (int a = 0; a < 3; ++a) j[a] = seam_cell_of_half(2 * bi[a] + ((o >> a) & 1), g[a]);
        f((j[2] * cells[1] + j[1]) * cells[0] + j[0], static_cast<std::size_t>(b) * 8 + o);
      }
    }
  }

  // Gathers the octants of seam cell c (its faces whose centroid's z-cell is in [z_lo, z_hi)),
  // joins them at equal keys, simplifies and emits.
  void seam_cell(std::int64_t c, std::int64_t z_lo, std::int64_t z_hi, TiledResult& result) {
    std::vector<SpillVertex> vs, chunk_vs;
    std::vector<Tri> fs, chunk_fs;
    std::vector<std::int64_t> local;
    for (std::size_t slot : cell_slots_[static_cast<std::size_t>(c)]) {
      for (const Chunk& ch : chunks_[slot]) {
        // The chunk's faces in the part (all of a whole cell's), and the vertices they use, in
        // the order of first use: a key met in several chunks keeps the chunks' order, so a
        // whole cell's quadrics add up as when its chunks were read whole.
        if (ch.z0 >= z_hi || ch.z0 + static_cast<std::int64_t>(ch.z_faces.size()) <= z_lo) continue;
        chunk_vs.resize(ch.vertices);
        chunks_spill_.read(ch.offset, chunk_vs.data(), ch.vertices * sizeof(SpillVertex));
        chunk_fs.resize(ch.faces);
        chunks_spill_.read(ch.offset + ch.vertices * sizeof(SpillVertex), chunk_fs.data(),
                           ch.faces * sizeof(Tri));
        local.assign(ch.vertices, -1);
        for (const Tri& t : chunk_fs) {
          const std::int64_t z = face_z_cell(chunk_vs[t[0]].position, chunk_vs[t[1]].position,
                                             chunk_vs[t[2]].position);
          if (z < z_lo || z >= z_hi) continue;
          Tri out;
          for (int i = 0; i < 3; ++i) {
            if (local[t[i]] < 0) {
              local[t[i]] = static_cast<std::int64_t>(vs.size());
              vs.push_back(chunk_vs[t[i]]);
            }
            out[i] = static_cast<std::uint32_t>(local[t[i]]);
          }
          fs.push_back(out);
        }
      }
    }
    chunk_vs = {};
    chunk_fs = {};
    if (fs.empty()) return;
    // Join at equal keys: a seam vertex comes once from each brick (or slice) around it, each
    // with the planes of that piece's faces.
    std::vector<std::uint32_t> order(vs.size());
    for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
      return vs[x].key < vs[y].key || (vs[x].key == vs[y].key && x < y);
    });
    MeshPiece piece;
    std::vector<std::uint32_t> merged(vs.size());
    for (std::size_t i = 0; i < order.size(); ++i) {
      const SpillVertex& v = vs[order[i]];
      if (i == 0 || v.key != vs[order[i - 1]].key) {
        piece.keys.push_back(v.key);
        piece.positions.push_back(v.position);
        piece.quadrics.push_back(v.quadric);
      } else {
        piece.quadrics.back() += v.quadric;
      }
      merged[order[i]] = static_cast<std::uint32_t>(piece.keys.size() - 1);
    }
    piece.triangles.reserve(fs.size());
    for (const Tri& t : fs) piece.triangles.push_back({merged[t[0]], merged[t[1]], merged[t[2]]});
    const std::uint64_t bytes =
        static_cast<std::uint64_t>(kSeamBytesPerFace * static_cast<double>(fs.size()));
    result.largest_brick_bytes = std::max(result.largest_brick_bytes, bytes);
    vs = {};
    fs = {};
    // Each cell aims at its share, less what the cells before it kept beyond theirs (a cell
    // whose locked boundary held faces back): the total lands on the target.
    const double share = keep_ * static_cast<double>(piece.triangles.size());
    const double aim = std::clamp(share - (kept_so_far_ - planned_so_far_), 0.8 * share,
                                  static_cast<double>(piece.triangles.size()));
    planned_so_far_ += share;
    const std::uint64_t before = result.triangles;
    emit(simplify_piece(std::move(piece),
                        std::max<std::uint64_t>(static_cast<std::uint64_t>(std::llround(aim)), 1),
                        sopt_, &result.simplify),
         result);
    kept_so_far_ += static_cast<double>(result.triangles - before);
  }

  // Streams a finished piece: vertices only it has go out now; vertices on its boundary (which
  // other cells may share) are kept by key and written at the end.
  void emit(const MeshPiece& p, TiledResult& result) {
    const std::vector<char> shared = boundary_vertices(p);
    std::vector<Vec3d> normal(normals_ ? p.positions.size() : 0, Vec3d{0, 0, 0});
    for (const Tri& t : p.triangles) {
      Vec3f q[3];
      for (int i = 0; i < 3; ++i)
        for (int a = 0; a < 3; ++a) q[i][a] = static_cast<float>(p.positions[t[i]][a]);
      quality_.add(radius_ratio(q[0], q[1], q[2]));
      if (normals_) {
        const Vec3d& a = p.positions[t[0]];
        const Vec3d& b = p.positions[t[1]];
        const Vec3d& c = p.positions[t[2]];
        const Vec3d u{b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const Vec3d v{c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        const Vec3d n{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                      u[0] * v[1] - u[1] * v[0]};
        for (std::uint32_t x : t)
          for (int k = 0; k < 3; ++k) normal[x][k] += n[k];
      }
    }
    // Final index of each vertex: interior ones in emission order; shared ones flagged with
    // their rank among shared vertices, resolved when the file is assembled.
    constexpr std::uint64_t kShared = std::uint64_t{1} << 63;
    std::vector<std::uint64_t> index(p.positions.size());
    std::vector<char> records;
    const std::size_t vbytes = normals_ ? 24 : 12;
    for (std::size_t v = 0; v < p.positions.size(); ++v) {
      if (shared[v]) {
        auto [it, fresh] = shared_.try_emplace(p.keys[v]);
        SharedVertex& sv = it->second;
        if (fresh) {
          // Held until the last unit that can meet it, then written at its rank. A vertex met
          // again after that would be written twice: an error, never a mesh with a crack.
          const std::int64_t last = last_unit(p.positions[v]);
          if (last < unit_)
            throw Error("the seams' pass met a vertex past the last cell that could hold it");
          sv.rank = shared_count_++;
          sv.position = p.positions[v];
          retiring_[static_cast<std::size_t>(last)].push_back(p.keys[v]);
        }
        if (normals_)
          for (int k = 0; k < 3; ++k) sv.normal[k] += normal[v][k];
        index[v] = kShared | sv.rank;
      } else {
        index[v] = interior_++;
        records.resize(records.size() + vbytes);
        char* r = records.data() + records.size() - vbytes;
        for (float x : frame_position(opt_.frame, to_float(p.positions[v]))) r = put_le(r, x);
        if (normals_) {
          const Vec3f n = frame_normal(opt_.frame, unit(normal[v]));
          for (float x : n) r = put_le(r, x);
        }
      }
    }
    if (!records.empty()) vertices_.append(records.data(), records.size());
    if (opt_.format == MeshFormat::Stl) {
      std::vector<char> tris(p.triangles.size() * kStlTriangleBytes);
      char* r = tris.data();
      for (Tri t : p.triangles) {
        if (opt_.frame.flip) std::swap(t[1], t[2]);
        Vec3f q[3];
        for (int i = 0; i < 3; ++i) q[i] = frame_position(opt_.frame, to_float(p.positions[t[i]]));
        r = put_stl_triangle(r, q[0], q[1], q[2]);
      }
      faces_.append(tris.data(), tris.size());
    } else {
      std::vector<std::uint64_t> ids;
      ids.reserve(3 * p.triangles.size());
      for (Tri t : p.triangles) {
        if (opt_.frame.flip) std::swap(t[1], t[2]);
        for (std::uint32_t v : t) ids.push_back(index[v]);
      }
      faces_.append(ids.data(), ids.size() * sizeof(std::uint64_t));
    }
    result.triangles += p.triangles.size();
  }

  static Vec3f unit(const Vec3d& n) {
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 0)) return {0, 0, 0};
    return {static_cast<float>(n[0] / len), static_cast<float>(n[1] / len),
            static_cast<float>(n[2] / len)};
  }

  // Copies `bytes` of a scratch file into the output, a block at a time.
  static void copy(const ScratchFile& from, std::uint64_t bytes, AtomicFile& to) {
    std::vector<char> block(static_cast<std::size_t>(std::min<std::uint64_t>(bytes, 1 << 20)));
    for (std::uint64_t at = 0; at < bytes;) {
      const std::size_t n =
          static_cast<std::size_t>(std::min<std::uint64_t>(block.size(), bytes - at));
      from.read(at, block.data(), n);
      to.write(block.data(), n);
      at += n;
    }
  }

  void assemble(const std::filesystem::path& output, TiledResult& result) {
    result.faces = result.triangles;
    result.vertices = interior_ + shared_count_;
    AtomicFile file(output);
    if (opt_.format == MeshFormat::Stl) {
      if (result.triangles > std::numeric_limits<std::uint32_t>::max())
        throw InputError("binary STL holds at most 2^32 - 1 triangles; this mesh has " +
                         std::to_string(result.triangles) + ": write PLY instead");
      char header[kStlHeaderBytes];
      stl_header(header, result.triangles);
      file.write(header, sizeof(header));
      copy(faces_, faces_.size(), file);
      file.commit();
      return;
    }
    const bool index64 = result.vertices > std::numeric_limits<std::uint32_t>::max();
    const std::string header = ply_header(result.vertices, result.faces, normals_, false, index64);
    file.write(header.data(), header.size());
    copy(vertices_, vertices_.size(), file);
    if (!shared_.empty()) throw Error("the seams' pass left vertices unwritten");
    copy(shared_spill_, shared_count_ * (normals_ ? 24 : 12), file);
    // Faces, with the shared vertices' ranks turned into indices after the interior ones.
    constexpr std::uint64_t kShared = std::uint64_t{1} << 63;
    const std::size_t per_block = 1 << 15;  // triangles
    std::vector<std::uint64_t> ids(3 * per_block);
    const std::size_t face_bytes = 1 + 3 * (index64 ? 8 : 4);
    std::vector<char> out(per_block * face_bytes);
    const std::uint64_t total = faces_.size() / (3 * sizeof(std::uint64_t));
    for (std::uint64_t f = 0; f < total; f += per_block) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(per_block, total - f));
      faces_.read(f * 3 * sizeof(std::uint64_t), ids.data(), n * 3 * sizeof(std::uint64_t));
      char* r = out.data();
      for (std::size_t i = 0; i < n; ++i) {
        *r++ = 3;
        for (int k = 0; k < 3; ++k) {
          std::uint64_t id = ids[3 * i + k];
          if (id & kShared) id = interior_ + (id & ~kShared);
          r = index64 ? put_le(r, id) : put_le(r, static_cast<std::uint32_t>(id));
        }
      }
      file.write(out.data(), static_cast<std::size_t>(r - out.data()));
    }
    file.commit();
  }

  // The seams' pass runs units (a seam cell, or one z-part of it) in order; a vertex on a unit's
  // boundary, shared with units to come, is held until the last unit whose faces can use it.
  // Held to the end, they grew with the volume: 2048x2048x512 at --memory 1GiB peaked at 1.46
  // times the budget. The last such unit is the one holding the point `reach_` + 1 beyond the
  // vertex along every axis: the seam cells and their parts are placed by face centroids, which
  // lie at most `reach_` from their vertices along each axis, and run z-major.
  void plan_units() {
    unit_base_.assign(cell_parts_.size() + 1, 0);
    for (std::size_t c = 0; c < cell_parts_.size(); ++c)
      unit_base_[c + 1] = unit_base_[c] + static_cast<std::int64_t>(cell_parts_[c].size()) + 1;
    retiring_.assign(static_cast<std::size_t>(unit_base_.back()), {});
    unit_ = 0;
  }

  // The seam cell along axis a of grid coordinate x: its brick's half (lower or upper, as spill()
  // splits by the brick's middle plane), grouped as for_each_octant() groups them.
  std::int64_t seam_cell_along(int a, double x) const {
    const std::int64_t bi =
        plan_.owner(a, std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor(x))));
    const std::int64_t lo = bi * plan_.brick[a];
    const double mid = 0.5 * static_cast<double>(lo + std::min(lo + plan_.brick[a], n_[a] - 1));
    return std::min(seam_cell_of_half(2 * bi + (x >= mid ? 1 : 0), seam_group_[a]),
                    seam_cells_along(a, seam_group_[a]) - 1);
  }

  std::int64_t last_unit(const Vec3d& p) const {
    const double far = reach_ + 1;
    std::int64_t j[3];
    for (int a = 0; a < 3; ++a) j[a] = seam_cell_along(a, grid_coord(p, a) + far);
    const std::int64_t c =
        (j[2] * seam_cells_along(1, seam_group_[1]) + j[1]) * seam_cells_along(0, seam_group_[0]) +
        j[0];
    const std::vector<std::int64_t>& cuts = cell_parts_[static_cast<std::size_t>(c)];
    const double z = std::floor(grid_coord(p, 2) + far);
    const auto part =
        std::upper_bound(cuts.begin(), cuts.end(), z,
                         [](double v, std::int64_t cut) { return v < static_cast<double>(cut); }) -
        cuts.begin();
    return unit_base_[static_cast<std::size_t>(c)] + part;
  }

  // Writes the vertices whose last unit was u at their ranks, and lets them go.
  void retire(std::int64_t u) {
    std::vector<std::uint64_t>& keys = retiring_[static_cast<std::size_t>(u)];
    const std::size_t vbytes = normals_ ? 24 : 12;
    for (const std::uint64_t key : keys) {
      const auto it = shared_.find(key);
      char buf[24];
      char* r = buf;
      for (float x : frame_position(opt_.frame, to_float(it->second.position))) r = put_le(r, x);
      if (normals_)
        for (float x : frame_normal(opt_.frame, unit(it->second.normal))) r = put_le(r, x);
      shared_spill_.write_at(it->second.rank * vbytes, buf, vbytes);
      shared_.erase(it);
    }
    keys = {};
  }

  struct SharedVertex {
    std::uint64_t rank = 0;
    Vec3d position{0, 0, 0};
    Vec3d normal{0, 0, 0};
  };

  VolumeSource& src_;
  const TiledOptions& opt_;
  Index3 n_;
  BrickReader reader_;
  std::filesystem::path dir_;
  ScratchFile chunks_spill_, vertices_, faces_;
  BrickPlan plan_;
  SimplifyOptions sopt_;
  bool normals_ = false;
  std::vector<std::vector<Chunk>> chunks_;            // per brick and octant
  Index3 seam_group_{1, 1, 1};                        // bricks per seam cell along each axis
  std::vector<std::vector<std::size_t>> cell_slots_;  // per seam cell: its octant slots
  // Per seam cell: the z planes (grid cells) it is cut at, none where it fits the budget whole.
  std::vector<std::vector<std::int64_t>> cell_parts_;
  std::uint64_t spilled_faces_ = 0;
  double keep_ = 1;  // fraction of the spilled faces the seam pass keeps
  double planned_so_far_ = 0, kept_so_far_ = 0;  // the seam cells' shares and what they kept
  // The seams' pass: vertices held by key, with their ranks among shared vertices.
  std::unordered_map<std::uint64_t, SharedVertex> shared_;
  std::uint64_t shared_count_ = 0;
  ScratchFile shared_spill_;  // their records, by rank
  double reach_ = 0;          // largest distance of a spilled face's centroid from a vertex of it
  std::vector<std::int64_t> unit_base_;               // first unit of each seam cell
  std::vector<std::vector<std::uint64_t>> retiring_;  // keys by their last unit
  std::int64_t unit_ = 0;                             // the unit running
  std::uint64_t interior_ = 0;
  QualityAccumulator quality_;
};

}  // namespace

TiledResult extract_tiled_simplified(VolumeSource& source, const TiledOptions& options,
                                     const std::filesystem::path& output) {
  return TiledSimplification(source, options, output).run(output);
}

}  // namespace isotile
