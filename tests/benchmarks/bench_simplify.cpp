// Simplification side by side: `isotile simplify` (a fresh process: read, simplify, write, as a
// user runs it), MeshLab 2020.09's Quadric Edge Collapse Decimation (meshlabserver, the reference
// of docs/simplify.md), OpenMesh 9's Decimater (quadric module alone, and with its normal-flipping
// and aspect-ratio modules) and meshoptimizer's meshopt_simplify, on the same input mesh, measured
// with the same measures: radius ratio, topology, and the two-way sampled distance to the input.
//
//   bench_simplify [--input MESH] [--ratio R] [--threads N] [--repeat K] [--isotile PATH]
//                  [--no-meshlab]
//
// Without --input it extracts bonsai (../shared/data) at 49.5 with Macet fast. Every contender
// runs K times, interleaved; the table gives the median wall time and, for the processes, the
// median CPU time (user + system, from wait4). The in-process contenders are timed from arrays in
// memory to arrays in memory, so their times leave out reading and writing files: a bound in
// their favour.
#include <fcntl.h>
#include <meshoptimizer.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <tbb/global_control.h>
#include <unistd.h>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModAspectRatioT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/extract/extract.h"
#include "core/mesh/mesh_io.h"
#include "core/mesh/mesh_quality.h"
#include "core/mesh/mesh_topology.h"
#include "core/mesh/surface_distance.h"
#include "core/volume/volume_io.h"

extern char** environ;

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct Timing {
  double wall = 0, cpu = -1;  // cpu < 0: not measured (in-process)
};

// Runs argv as a child process; returns its wall and CPU time, or nullopt when it failed.
std::optional<Timing> run_process(const std::vector<std::string>& args,
                                  const std::vector<std::string>& env_extra = {}) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::vector<std::string> env_store;
  for (char** e = environ; *e; ++e) env_store.emplace_back(*e);
  for (const auto& e : env_extra) env_store.push_back(e);
  std::vector<char*> envp;
  for (auto& e : env_store) envp.push_back(e.data());
  envp.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  const auto t0 = Clock::now();
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, argv[0], &actions, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) return std::nullopt;
  int status = 0;
  rusage usage{};
  if (wait4(pid, &status, 0, &usage) < 0) return std::nullopt;
  Timing t;
  t.wall = std::chrono::duration<double>(Clock::now() - t0).count();
  t.cpu = static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
          1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return std::nullopt;
  return t;
}

// An X server for meshlabserver, started once: its start-up is not MeshLab's time.
class Xvfb {
 public:
  Xvfb() {
    for (int d = 90; d < 110; ++d) {
      if (fs::exists("/tmp/.X11-unix/X" + std::to_string(d))) continue;
      display_ = ":" + std::to_string(d);
      const std::string disp = display_;
      char* argv[] = {const_cast<char*>("Xvfb"), const_cast<char*>(disp.c_str()),
                      const_cast<char*>("-nolisten"), const_cast<char*>("tcp"), nullptr};
      posix_spawn_file_actions_t actions;
      posix_spawn_file_actions_init(&actions);
      posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
      if (posix_spawnp(&pid_, "Xvfb", &actions, nullptr, argv, environ) != 0) pid_ = 0;
      posix_spawn_file_actions_destroy(&actions);
      for (int i = 0; i < 50 && pid_ > 0; ++i) {
        if (fs::exists("/tmp/.X11-unix/X" + std::to_string(d))) return;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
      break;
    }
    display_.clear();
  }
  ~Xvfb() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      waitpid(pid_, nullptr, 0);
    }
  }
  const std::string& display() const { return display_; }

 private:
  pid_t pid_ = 0;
  std::string display_;
};

struct Row {
  explicit Row(std::string n) : name(std::move(n)) {}
  std::string name;
  std::vector<Timing> times;
  isotile::Mesh mesh;
  bool ok = false;
};

double median(std::vector<double> v) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// --- OpenMesh and meshoptimizer, in process -------------------------------------------------

using OMesh = OpenMesh::TriMesh_ArrayKernelT<>;

isotile::Mesh openmesh_decimate(const isotile::Mesh& in, std::size_t target, bool shape_modules) {
  OMesh m;
  std::vector<OMesh::VertexHandle> vh;
  vh.reserve(in.positions.size());
  for (const auto& p : in.positions) vh.push_back(m.add_vertex({p[0], p[1], p[2]}));
  for (const auto& t : in.triangles) m.add_face(vh[t[0]], vh[t[1]], vh[t[2]]);
  OpenMesh::Decimater::DecimaterT<OMesh> dec(m);
  OpenMesh::Decimater::ModQuadricT<OMesh>::Handle quadric;
  dec.add(quadric);
  OpenMesh::Decimater::ModNormalFlippingT<OMesh>::Handle flipping;
  OpenMesh::Decimater::ModAspectRatioT<OMesh>::Handle aspect;
  if (shape_modules) {
    dec.add(flipping);
    dec.add(aspect);
    dec.module(aspect).set_aspect_ratio(5);
    dec.module(aspect).set_binary(true);
    // Border vertices stay (isotile and MeshLab's run keep the border).
    m.request_vertex_status();
    for (auto v : m.vertices())
      if (m.is_boundary(v)) m.status(v).set_locked(true);
  }
  dec.initialize();
  dec.decimate_to_faces(0, target);
  m.garbage_collection();
  isotile::Mesh out;
  for (auto v : m.vertices()) {
    const auto& p = m.point(v);
    out.positions.push_back({p[0], p[1], p[2]});
  }
  for (auto f : m.faces()) {
    isotile::Tri t;
    int k = 0;
    for (auto v : m.fv_range(f)) t[k++] = static_cast<std::uint32_t>(v.idx());
    out.triangles.push_back(t);
  }
  return out;
}

isotile::Mesh meshopt(const isotile::Mesh& in, std::size_t target) {
  std::vector<unsigned> idx;
  for (const auto& t : in.triangles) idx.insert(idx.end(), t.begin(), t.end());
  std::vector<unsigned> out_idx(idx.size());
  const std::size_t n = meshopt_simplify(
      out_idx.data(), idx.data(), idx.size(), in.positions[0].data(), in.positions.size(),
      sizeof(isotile::Vec3f), target * 3, 1.0f, meshopt_SimplifyLockBorder, nullptr);
  isotile::Mesh out;
  out.positions = in.positions;
  for (std::size_t i = 0; i + 2 < n; i += 3)
    out.triangles.push_back({out_idx[i], out_idx[i + 1], out_idx[i + 2]});
  // Drop the unreferenced vertices, as a file round trip would.
  std::vector<std::int64_t> map(out.positions.size(), -1);
  isotile::Mesh compact;
  for (auto& t : out.triangles)
    for (auto& v : t) {
      if (map[v] < 0) {
        map[v] = static_cast<std::int64_t>(compact.positions.size());
        compact.positions.push_back(out.positions[v]);
      }
      v = static_cast<std::uint32_t>(map[v]);
    }
  compact.triangles = out.triangles;
  return compact;
}

const char* kMeshlabScript = R"(<!DOCTYPE FilterScript>
<FilterScript>
 <filter name="Simplification: Quadric Edge Collapse Decimation">
  <Param type="RichInt" name="TargetFaceNum" value="%zu"/>
  <Param type="RichFloat" name="TargetPerc" value="0"/>
  <Param type="RichFloat" name="QualityThr" value="0.3"/>
  <Param type="RichBool" name="PreserveBoundary" value="true"/>
  <Param type="RichFloat" name="BoundaryWeight" value="1"/>
  <Param type="RichBool" name="PreserveNormal" value="true"/>
  <Param type="RichBool" name="PreserveTopology" value="true"/>
  <Param type="RichBool" name="OptimalPlacement" value="true"/>
  <Param type="RichBool" name="PlanarQuadric" value="false"/>
  <Param type="RichFloat" name="PlanarWeight" value="0.001"/>
  <Param type="RichBool" name="QualityWeight" value="false"/>
  <Param type="RichBool" name="AutoClean" value="true"/>
  <Param type="RichBool" name="Selected" value="false"/>
 </filter>
</FilterScript>
)";

}  // namespace

int main(int argc, char** argv) {
  std::string input, isotile = "build/tiler/isotile";
  double ratio = 0.1;
  int threads = 2, repeat = 1;
  bool meshlab = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_simplify: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--input")
      input = next();
    else if (a == "--ratio")
      ratio = std::stod(next());
    else if (a == "--threads")
      threads = std::stoi(next());
    else if (a == "--repeat")
      repeat = std::stoi(next());
    else if (a == "--isotile")
      isotile = next();
    else if (a == "--no-meshlab")
      meshlab = false;
    else {
      std::fprintf(stderr,
                   "usage: bench_simplify [--input MESH] [--ratio R] [--threads N] [--repeat K] "
                   "[--isotile PATH] [--no-meshlab]\n");
      return 2;
    }
  }
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
  const fs::path dir = fs::temp_directory_path() / ("bench_simplify_" + std::to_string(getpid()));
  fs::create_directories(dir);
  if (input.empty()) {
    const fs::path bonsai = fs::path(ISOTILE_SHARED_DATA) / "bonsai_256x256x256_uint8.raw.gz";
    if (!fs::exists(bonsai)) {
      std::printf("bench_simplify: no %s; pass --input MESH\n", bonsai.c_str());
      return 0;
    }
    const isotile::Volume vol = isotile::read_volume(bonsai.string());
    isotile::ExtractOptions o;
    o.method = isotile::Method::Macet;
    o.iso = 49.5;
    o.backend = isotile::Backend::Cpu;
    input = (dir / "bonsai-macet.ply").string();
    isotile::write_mesh(isotile::extract(vol.view(), o), input);
  }
  const isotile::Mesh in = isotile::read_mesh(input);
  const std::size_t target =
      static_cast<std::size_t>(std::llround(ratio * static_cast<double>(in.triangles.size())));
  std::printf("input %s: %zu triangles, %zu vertices; target %zu; %d threads; %d run(s) each\n",
              input.c_str(), in.triangles.size(), in.positions.size(), target, threads, repeat);

  std::vector<Row> rows;
  rows.emplace_back("isotile simplify (CLI)");
  std::optional<Xvfb> x;
  const fs::path script = dir / "qecd.mlx";
  if (meshlab) {
    x.emplace();
    if (x->display().empty()) {
      std::printf("no Xvfb: MeshLab left out\n");
      meshlab = false;
    } else {
      FILE* f = std::fopen(script.c_str(), "w");
      std::fprintf(f, kMeshlabScript, target);
      std::fclose(f);
      rows.emplace_back("MeshLab 2020.09 QECD (meshlabserver)");
    }
  }
  rows.emplace_back("OpenMesh Decimater, quadric");
  rows.emplace_back("OpenMesh Decimater, quadric + normal flip + aspect 5");
  rows.emplace_back("meshoptimizer (LockBorder, error 1)");

  for (int rep = 0; rep < repeat; ++rep) {
    for (Row& row : rows) {
      const fs::path out = dir / "out.ply";
      std::optional<Timing> t;
      if (row.name.starts_with("isotile")) {
        t = run_process({isotile, "-q", "--threads", std::to_string(threads), "simplify", input,
                         out.string(), "--ratio", std::to_string(ratio)});
        if (t) row.mesh = isotile::read_mesh(out);
      } else if (row.name.starts_with("MeshLab")) {
        t = run_process({"meshlabserver", "-i", input, "-o", out.string(), "-s", script.string()},
                        {"DISPLAY=" + x->display()});
        if (t) row.mesh = isotile::read_mesh(out);
      } else {
        const auto t0 = Clock::now();
        if (row.name.starts_with("meshopt"))
          row.mesh = meshopt(in, target);
        else
          row.mesh = openmesh_decimate(in, target, row.name.find("flip") != std::string::npos);
        t = Timing{std::chrono::duration<double>(Clock::now() - t0).count(), -1};
      }
      if (t) {
        row.times.push_back(*t);
        row.ok = true;
      } else {
        std::printf("%s failed\n", row.name.c_str());
      }
      fs::remove(out);
    }
  }

  std::printf(
      "\n| simplifier | wall s | CPU s | triangles | min | q0.1%% | mean | non-manifold edges | "
      "components | boundary edges | distance mean | distance max |\n");
  std::printf("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
  const isotile::TopologyStats tin = isotile::mesh_topology(in);
  const isotile::QualityStats qin = isotile::triangle_quality(in);
  std::printf("| input | | | %zu | %.4f | %.3f | %.3f | %llu | %llu | %llu | | |\n",
              in.triangles.size(), qin.min, qin.q001, qin.mean,
              static_cast<unsigned long long>(tin.nonmanifold_edges),
              static_cast<unsigned long long>(tin.components),
              static_cast<unsigned long long>(tin.boundary_edges));
  double isotile_wall = -1, meshlab_cpu = -1;
  for (const Row& row : rows) {
    if (!row.ok) continue;
    std::vector<double> wall, cpu;
    for (const Timing& t : row.times) {
      wall.push_back(t.wall);
      if (t.cpu >= 0) cpu.push_back(t.cpu);
    }
    const isotile::QualityStats q = isotile::triangle_quality(row.mesh);
    const isotile::TopologyStats t = isotile::mesh_topology(row.mesh);
    const isotile::SurfaceDistance d = isotile::surface_distance(in, row.mesh);
    const double w = median(wall), c = median(cpu);
    if (row.name.starts_with("isotile")) isotile_wall = w;
    if (row.name.starts_with("MeshLab")) meshlab_cpu = c;
    std::printf(
        "| %s | %.2f | %s | %zu | %.4f | %.3f | %.3f | %llu | %llu | %llu | %.3f | %.2f |\n",
        row.name.c_str(), w, c >= 0 ? std::to_string(c).substr(0, 5).c_str() : "",
        row.mesh.triangles.size(), q.min, q.q001, q.mean,
        static_cast<unsigned long long>(t.nonmanifold_edges),
        static_cast<unsigned long long>(t.components),
        static_cast<unsigned long long>(t.boundary_edges), d.mean(), d.max());
  }
  if (isotile_wall > 0 && meshlab_cpu > 0)
    std::printf("\nisotile wall / MeshLab CPU: %.3f (target <= 0.25)\n",
                isotile_wall / meshlab_cpu);
  fs::remove_all(dir);
  return 0;
}
