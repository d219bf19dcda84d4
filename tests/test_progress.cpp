// Progress and cancel (core/progress.h): every long loop reports in units of work (z-slices of
// rows, bytes, faces, collapse rounds), so these tests count the callbacks per unit of work
// instead of timing them; a callback answering false stops the work with Cancelled, and nothing
// is left behind.
#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "core/extract/extract.h"
#include "core/mesh/mesh_io.h"
#include "core/progress.h"
#include "core/simplify/simplify.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "test_support.h"
#include "tiler/tiled_extract.h"
#include "tiler/volume_source.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

// Records every update; answers false from the `stop_at`-th call on (1-based; 0: never), or
// from the first update that `stop_when` accepts on.
struct Recorder {
  std::vector<ProgressUpdate> updates;
  std::int64_t stop_at = 0;
  std::int64_t calls_after_stop = 0;
  std::function<bool(const ProgressUpdate&)> stop_when;
  bool stopped = false;
  ProgressCallback callback() {
    return [this](const ProgressUpdate& u) {
      updates.push_back(u);
      const auto n = static_cast<std::int64_t>(updates.size());
      if (stop_at > 0 && n > stop_at) ++calls_after_stop;
      if (stop_when && !stopped) stopped = stop_when(u);
      return !stopped && (stop_at == 0 || n < stop_at);
    };
  }
  // Callbacks of `stage`.
  std::int64_t count(Stage stage) const {
    std::int64_t n = 0;
    for (const auto& u : updates) n += u.stage == stage;
    return n;
  }
};

// Within each run of a stage (from its begin(): fraction 0) the fraction grows from 0 to 1, and
// every run ends at 1 (the units counted add up to the stage's total).
void expect_monotonic_runs(const std::vector<ProgressUpdate>& updates, const std::string& what) {
  ASSERT_FALSE(updates.empty()) << what;
  for (std::size_t i = 0; i < updates.size(); ++i) {
    const ProgressUpdate& u = updates[i];
    EXPECT_GE(u.fraction, 0.0) << what << " call " << i;
    EXPECT_LE(u.fraction, 1.0) << what << " call " << i;
    const bool starts = i == 0 || updates[i - 1].stage != u.stage || u.fraction == 0;
    if (starts) {
      EXPECT_EQ(u.fraction, 0.0) << what << ": stage " << stage_name(u.stage) << " call " << i
                                 << " does not start at 0";
      if (i > 0) {
        EXPECT_EQ(updates[i - 1].fraction, 1.0)
            << what << ": stage " << stage_name(updates[i - 1].stage) << " ended below 1";
      }
    } else {
      EXPECT_GE(u.fraction, updates[i - 1].fraction)
          << what << ": stage " << stage_name(u.stage) << " went back at call " << i;
    }
  }
  EXPECT_EQ(updates.back().fraction, 1.0) << what << ": the last stage ended below 1";
}

struct MethodCase {
  const char* name;
  ExtractOptions options;
};

std::vector<MethodCase> methods() {
  ExtractOptions mc;
  mc.method = Method::MarchingCubes;
  ExtractOptions fast = mc;
  fast.method = Method::Macet;
  ExtractOptions max = fast;
  max.quality = MacetQuality::Max;
  ExtractOptions dc = mc;
  dc.method = Method::DualContouring;
  for (ExtractOptions* o : {&mc, &fast, &max, &dc}) {
    o->backend = Backend::Cpu;
    o->iso = 0;
  }
  return {{"mc", mc}, {"macet fast", fast}, {"macet max", max}, {"dc", dc}};
}

constexpr int kSlices = 40;  // z-slices of the test field

// The contract's unit: a z-slice of rows. Each stage of an extraction passes over every z-slice
// at least once, so it reports at least once per z-slice: kSlices callbacks or more.
TEST(Progress, ExtractorsReportPerZSliceAndGrowMonotonically) {
  const Volume volume = make_field_volume({FieldKind::Gyroid, kSlices});
  for (MethodCase m : methods()) {
    Recorder rec;
    Progress progress(rec.callback());
    m.options.progress = &progress;
    const Mesh with = extract(volume.view(), m.options);
    m.options.progress = nullptr;
    const Mesh without = extract(volume.view(), m.options);
    // Reporting changes nothing in the result.
    EXPECT_EQ(with.positions, without.positions) << m.name;
    EXPECT_EQ(with.triangles, without.triangles) << m.name;
    EXPECT_GE(rec.count(Stage::Count), kSlices) << m.name;
    EXPECT_GE(rec.count(Stage::Extract), kSlices) << m.name;
    if (m.options.quality == MacetQuality::Max && m.options.method == Method::Macet)
      EXPECT_GE(rec.count(Stage::MacetSearch), kSlices) << m.name;
    else
      EXPECT_EQ(rec.count(Stage::MacetSearch), 0) << m.name;
    for (const auto& u : rec.updates) {
      EXPECT_EQ(u.brick, 0);
      EXPECT_EQ(u.bricks, 1);
    }
    expect_monotonic_runs(rec.updates, m.name);
  }
}

// A callback answering false stops the extraction with Cancelled; the other workers stop at
// their next unit: at most one more callback per thread (one may be waiting for the lock).
TEST(Progress, ExtractorsStopWithCancelled) {
  const Volume volume = make_field_volume({FieldKind::Gyroid, kSlices});
  const auto threads = static_cast<std::int64_t>(tbb::this_task_arena::max_concurrency());
  for (MethodCase m : methods()) {
    for (std::int64_t k : {1, 5, 60}) {
      Recorder rec;
      rec.stop_at = k;
      Progress progress(rec.callback());
      m.options.progress = &progress;
      EXPECT_THROW(extract(volume.view(), m.options), Cancelled) << m.name << " k " << k;
      EXPECT_TRUE(progress.cancelled());
      EXPECT_GE(static_cast<std::int64_t>(rec.updates.size()), k) << m.name;
      EXPECT_LE(rec.calls_after_stop, threads) << m.name << " k " << k;
    }
  }
}

// cancel() from outside (a signal handler, another thread) stops the next unit.
TEST(Progress, CancelFromOutsideStops) {
  const Volume volume = make_field_volume({FieldKind::Gyroid, kSlices});
  Progress progress;
  progress.cancel();
  ExtractOptions o;
  o.backend = Backend::Cpu;
  o.progress = &progress;
  EXPECT_THROW(extract(volume.view(), o), Cancelled);
}

// A child reports as its brick of the parent's stage: growing, below 1 until finish(), and it
// shares the parent's cancel.
TEST(Progress, ChildReportsWithinItsBrick) {
  Recorder rec;
  Progress root(rec.callback());
  {
    Progress child(root, Stage::Extract, 3, 8);
    child.begin(Stage::Count, 4);
    for (int i = 0; i < 4; ++i) child.advance();
    child.begin(Stage::Extract, 2);
    child.advance(2);
    child.finish();
  }
  ASSERT_EQ(rec.updates.size(), 8u);  // two begins, five advances, the finish
  for (std::size_t i = 0; i < rec.updates.size(); ++i) {
    const ProgressUpdate& u = rec.updates[i];
    EXPECT_EQ(u.stage, Stage::Extract);
    EXPECT_EQ(u.brick, 3);
    EXPECT_EQ(u.bricks, 8);
    if (i > 0) {
      EXPECT_GE(u.fraction, rec.updates[i - 1].fraction) << i;
    }
    if (i + 1 < rec.updates.size()) {
      EXPECT_LT(u.fraction, 1.0) << i;
    }
  }
  EXPECT_EQ(rec.updates.back().fraction, 1.0);

  Progress child(root, Stage::Count, 0, 2);
  root.cancel();
  EXPECT_TRUE(child.cancelled());
  EXPECT_THROW(child.advance(), Cancelled);
}

// A share reports its stages as its part of the parent's current one, in the parent's brick; in
// a child, as the child's own stage within its brick.
TEST(Progress, SharesReportTheirPartOfTheStage) {
  Recorder rec;
  Progress root(rec.callback());
  for (const auto& [from, to] : {std::pair{0.0, 0.25}, std::pair{0.25, 1.0}}) {
    Progress share(root, from, to);
    share.begin(Stage::Simplify, 2);
    share.advance(2);
  }
  const std::vector<double> want = {0, 0.25, 0.25, 1};
  ASSERT_EQ(rec.updates.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(rec.updates[i].stage, Stage::Simplify) << i;
    EXPECT_DOUBLE_EQ(rec.updates[i].fraction, want[i]) << i;
  }
  rec.updates.clear();
  Progress child(root, Stage::Simplify, 2, 5);
  Progress share(child, 0.5, 1.0);
  share.begin(Stage::Simplify, 1);
  share.advance();
  ASSERT_EQ(rec.updates.size(), 2u);
  for (const ProgressUpdate& u : rec.updates) {
    EXPECT_EQ(u.brick, 2);
    EXPECT_EQ(u.bricks, 5);
    EXPECT_LT(u.fraction, 1.0);
  }
  EXPECT_LT(rec.updates[0].fraction, rec.updates[1].fraction);
  root.cancel();
  EXPECT_THROW(share.advance(), Cancelled);
}

// A stop condition beside the callback: asked after it at every report, a child's included; true
// cancels the run; cleared, it is asked no more.
TEST(Progress, StopWhenCancelsAtTheNextReport) {
  int asked = 0;
  bool stop = false;
  Progress root([](const ProgressUpdate&) { return true; });
  root.set_stop_when([&] {
    ++asked;
    return stop;
  });
  root.begin(Stage::Read, 4);
  root.advance();
  EXPECT_EQ(asked, 2);
  {
    Progress child(root, Stage::Extract, 0, 2);
    child.begin(Stage::Count, 2);
    EXPECT_EQ(asked, 3);
    stop = true;
    EXPECT_THROW(child.advance(), Cancelled);
    EXPECT_EQ(asked, 4);
  }
  EXPECT_TRUE(root.cancelled());

  Progress silent;  // no callback: still asked
  silent.set_stop_when([] { return true; });
  EXPECT_THROW(silent.begin(Stage::Read, 1), Cancelled);
  Progress cleared;
  cleared.set_stop_when([] { return true; });
  cleared.set_stop_when({});
  cleared.begin(Stage::Read, 1);
  cleared.advance();
  EXPECT_FALSE(cleared.cancelled());
}

class ProgressFiles : public isotile::testing::TempDirTest {
 protected:
  ProgressFiles() : TempDirTest("isotile-progress-") {}
  // The names in the work directory (a cancelled write must leave none but the inputs).
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir_)) out.push_back(e.path().filename().string());
    return out;
  }
};

// 32 MiB of raw samples: read in 4 MiB units with a Progress, so at least 8 callbacks after the
// begin; the samples are the same as without one.
TEST_F(ProgressFiles, ReadingARawFileReportsPerUnitOfBytes) {
  const Index3 dims{256, 256, 128};
  const fs::path path = dir_ / "ramp_256x256x128_float32.raw";
  std::vector<float> samples(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]));
  for (std::size_t i = 0; i < samples.size(); ++i) samples[i] = static_cast<float>(i % 1000);
  {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(samples.data()),
              static_cast<std::streamsize>(samples.size() * sizeof(float)));
  }
  Recorder rec;
  Progress progress(rec.callback());
  RawOptions raw;
  raw.progress = &progress;
  const Volume v = read_volume(path.string(), raw);
  EXPECT_EQ(std::memcmp(v.bytes(), samples.data(), samples.size() * sizeof(float)), 0);
  EXPECT_GE(rec.count(Stage::Read), 1 + 8);
  expect_monotonic_runs(rec.updates, "raw read");

  Recorder stop;
  stop.stop_at = 3;
  Progress cancelling(stop.callback());
  raw.progress = &cancelling;
  EXPECT_THROW(read_volume(path.string(), raw), Cancelled);
}

// Writing reports per chunk of 8192 vertices or faces; cancelled, it leaves no file and no
// temporary beside it.
TEST_F(ProgressFiles, WritingReportsPerChunkAndCancelLeavesNothing) {
  const Mesh mesh = extract(make_field_volume({FieldKind::Gyroid, 96}).view(), {.iso = 0});
  ASSERT_GT(mesh.triangles.size(), 10u * 8192);
  for (const char* name : {"m.ply", "m.stl", "m.obj", "m.off"}) {
    Recorder rec;
    Progress progress(rec.callback());
    write_mesh(mesh, dir_ / name, {.format = std::nullopt, .progress = &progress});
    EXPECT_GE(rec.count(Stage::Write), 10) << name;
    expect_monotonic_runs(rec.updates, name);
    fs::remove(dir_ / name);

    Recorder stop;
    stop.stop_at = 4;
    Progress cancelling(stop.callback());
    EXPECT_THROW(write_mesh(mesh, dir_ / name, {.format = std::nullopt, .progress = &cancelling}),
                 Cancelled)
        << name;
    EXPECT_TRUE(names().empty()) << name << " left " << names().front();
  }
}

// Simplification reports its rounds of collapses (not only the regions) and stops when asked.
TEST(Progress, SimplifyReportsRoundsAndStops) {
  const Mesh mesh = extract(make_field_volume({FieldKind::Gyroid, 48}).view(), {.iso = 0});
  SimplifyOptions o;
  o.ratio = 0.1;
  Recorder rec;
  Progress progress(rec.callback());
  o.progress = &progress;
  const Mesh with = simplify(mesh, o);
  o.progress = nullptr;
  EXPECT_EQ(with.triangles, simplify(mesh, o).triangles);
  expect_monotonic_runs(rec.updates, "simplify");
  // The two passes as one stage, each in its share: it starts at 0 once and never goes back (the
  // second pass started it again at 0 after the first reached 1).
  EXPECT_EQ(std::count_if(rec.updates.begin(), rec.updates.end(),
                          [](const ProgressUpdate& u) { return u.fraction == 0; }),
            1);
  EXPECT_EQ(std::count_if(rec.updates.begin(), rec.updates.end(),
                          [](const ProgressUpdate& u) { return u.fraction == 1; }),
            1);
  // Per pass: its begin, rounds of collapses and then one per region finished; more calls than
  // regions alone would make.
  std::int64_t below_regions = 0;
  for (const auto& u : rec.updates) below_regions += u.fraction > 0 && u.fraction < 0.5;
  EXPECT_GE(below_regions, 2) << "no round of collapses reported";

  for (std::int64_t k : {1, 3, 10}) {
    Recorder stop;
    stop.stop_at = k;
    Progress cancelling(stop.callback());
    o.progress = &cancelling;
    EXPECT_THROW(simplify(mesh, o), Cancelled) << k;
  }
}

// Out of core: cancelled in either pass, no output file and no temporary are left.
TEST_F(ProgressFiles, TiledExtractionCancelledLeavesNothing) {
  const std::string input = "field:gyroid:64";
  TiledOptions to;
  to.extract.iso = 0;
  to.extract.backend = Backend::Cpu;
  to.memory = std::uint64_t{1} << 20;  // many bricks
  const fs::path out = dir_ / "tiled.ply";

  Recorder rec;
  Progress progress(rec.callback());
  to.progress = &progress;
  const TiledResult r = extract_tiled(*open_volume_source(input, {}), to, out);
  ASSERT_GT(r.plan.total(), 4);
  ASSERT_TRUE(fs::exists(out));
  fs::remove(out);
  // Every brick counted and extracted is reported done once; the extraction inside a brick
  // reports too, below 1, for its own brick.
  std::map<std::pair<Stage, std::int64_t>, int> done;
  std::map<std::pair<Stage, std::int64_t>, double> last;
  for (const auto& u : rec.updates) {
    EXPECT_EQ(u.bricks, r.plan.total());
    const auto key = std::pair(u.stage, u.brick);
    if (last.count(key)) {
      EXPECT_GE(u.fraction, last[key]);
    }
    last[key] = u.fraction;
    done[key] += u.fraction == 1.0;
  }
  for (std::int64_t b = 0; b < r.plan.total(); ++b) {
    EXPECT_EQ((done[{Stage::Count, b}]), 1) << b;
    EXPECT_EQ((done[{Stage::Extract, b}]), 1) << b;
  }
  EXPECT_GT(rec.updates.size(), 2 * static_cast<std::size_t>(r.plan.total()));

  const auto calls = static_cast<std::int64_t>(rec.updates.size());
  const std::int64_t last_brick = r.plan.total() - 1;
  // At a few call counts, and (k = 0) as the last brick's extraction begins: the number of calls
  // changes from run to run (the parallel loops' ranges are cut into pieces as TBB splits them),
  // so a count near the end may never be reached.
  for (std::int64_t k : {std::int64_t{1}, calls / 4, calls / 2, std::int64_t{0}}) {
    for (std::uint64_t overlap : {std::uint64_t{0}, ~std::uint64_t{0}}) {
      Recorder stop;
      stop.stop_at = k;
      if (k == 0)
        stop.stop_when = [last_brick](const ProgressUpdate& u) {
          return u.stage == Stage::Extract && u.brick == last_brick;
        };
      Progress cancelling(stop.callback());
      to.progress = &cancelling;
      to.overlap_min_memory = overlap;
      EXPECT_THROW(extract_tiled(*open_volume_source(input, {}), to, out), Cancelled) << k;
      EXPECT_TRUE(names().empty()) << k << " left " << names().front();
    }
  }
}

// Out of core with --simplify: the bricks' extraction and simplification report within their
// brick; cancelled anywhere, neither the output, its temporary nor a scratch file is left.
TEST_F(ProgressFiles, TiledSimplificationCancelledLeavesNothing) {
  TiledOptions to;
  to.extract.iso = 0;
  to.extract.backend = Backend::Cpu;
  to.memory = std::uint64_t{1} << 20;
  to.simplify = 0.3;
  const fs::path out = dir_ / "simplified.ply";
  Recorder rec;
  Progress progress(rec.callback());
  to.progress = &progress;
  const TiledResult r = extract_tiled(*open_volume_source("field:gyroid:48", {}), to, out);
  ASSERT_GT(r.plan.total(), 2);
  fs::remove(out);
  std::map<std::int64_t, int> simplified;
  for (const auto& u : rec.updates)
    if (u.stage == Stage::Simplify && u.bricks > 1) simplified[u.brick] += u.fraction == 1.0;
  for (std::int64_t b = 0; b < r.plan.total(); ++b) EXPECT_EQ(simplified[b], 1) << b;
  // Reports inside the bricks too, not only one per brick.
  EXPECT_GT(rec.updates.size(), 4 * static_cast<std::size_t>(r.plan.total()));
  // The seams' pass follows every brick as a stage of its own, 0 to 1 and only growing (reported
  // as `simplify` of one brick, its fraction restarted from 0 after the bricks' `simplify`).
  std::size_t last_brick_report = 0, first_seam = rec.updates.size();
  for (std::size_t i = 0; i < rec.updates.size(); ++i) {
    const ProgressUpdate& u = rec.updates[i];
    if (u.stage == Stage::Simplify) {
      EXPECT_GT(u.bricks, 1) << i;
      last_brick_report = i;
    }
    if (u.stage == Stage::SimplifySeams) first_seam = std::min(first_seam, i);
  }
  ASSERT_LT(first_seam, rec.updates.size());
  EXPECT_GT(first_seam, last_brick_report);
  EXPECT_EQ(rec.updates[first_seam].fraction, 0.0);
  double seam_fraction = 0;
  for (std::size_t i = first_seam; i < rec.updates.size(); ++i)
    if (rec.updates[i].stage == Stage::SimplifySeams) {
      EXPECT_EQ(rec.updates[i].bricks, 1) << i;
      EXPECT_GE(rec.updates[i].fraction, seam_fraction) << i;
      seam_fraction = rec.updates[i].fraction;
    }
  EXPECT_EQ(seam_fraction, 1.0);

  const auto calls = static_cast<std::int64_t>(rec.updates.size());
  const std::int64_t last_brick = r.plan.total() - 1;
  // At a few call counts, and (k = 0) as the last brick's simplification begins (the number of
  // calls changes from run to run: a count near the end may never be reached).
  for (std::int64_t k : {std::int64_t{1}, calls / 3, calls * 2 / 3, std::int64_t{0}}) {
    Recorder stop;
    stop.stop_at = k;
    if (k == 0)
      stop.stop_when = [last_brick](const ProgressUpdate& u) {
        return u.stage == Stage::Simplify && u.bricks > 1 && u.brick == last_brick;
      };
    Progress cancelling(stop.callback());
    to.progress = &cancelling;
    EXPECT_THROW(extract_tiled(*open_volume_source("field:gyroid:48", {}), to, out), Cancelled)
        << k;
    EXPECT_TRUE(names().empty()) << k << " left " << names().front();
  }
}

}  // namespace
}  // namespace isotile
