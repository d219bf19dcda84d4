// Progress and cancellation for the library's long work.
//
// A run (one extraction, one simplification, one file written) owns one Progress built from the
// caller's callback and hands a pointer to it down through the options structs of the work it
// calls (ExtractOptions::progress, TiledOptions::progress, SimplifyOptions::progress, ...). Every
// long loop counts its work in units it knows (z-slices of cells, bricks, collapse rounds, bytes)
// and reports them with advance(); a unit is sized to take well under 0.1 s on one thread, so the
// callback hears from the work at least that often, and tests count calls per unit of work
// instead of timing them. A null Progress* means nobody listens: loops skip the calls.
//
// The callback returns false to cancel. The library then throws Cancelled out of the loop and out
// of every thread working for it (TBB carries the exception to the caller), and whatever was being
// written is removed (core/mesh/atomic_file.h): a cancelled run leaves nothing behind.
//
// Parallel loops report through for_units() below: the workers advance once per unit (a z-slice
// of rows, a chunk of faces), never per cell, so the inner loops keep their speed; a worker checks
// for cancel before each unit. Within one begin() of a stage the fraction only grows, 0 to 1.
//
// Nesting: work done for one brick of a larger run (the tiler) reports through a child Progress
// (Progress(parent, stage, brick, bricks)) so that bricks in flight at once do not clobber each
// other's stage: the child's own stages (read, count, extract of the core extraction inside the
// brick) become a growing fraction below 1 of the parent's `stage` for that brick, and finish()
// reports the brick done (fraction 1). Children share their parent's cancel.
//
// Shares: work done in passes within one stage (the simplifier's two) reports each pass through a
// share of its Progress (Progress(parent, from, to)), whose stage's fraction, 0 to 1, is told to
// the parent as from to `to`: the stage's fraction only grows across the passes, where each
// pass's begin() started it again at 0.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>

#include "core/errors.h"

namespace isotile {

// The stages of a run, in the order a run usually meets them.
// SimplifySeams: the out-of-core simplification's last pass, over the cells that straddle its
// bricks' seams (after Simplify, brick by brick).
enum class Stage { Read, Histogram, Count, Extract, MacetSearch, Simplify, SimplifySeams, Write };
std::string_view stage_name(Stage stage);  // "read", "histogram", "count", "extract", ...

// Stages whose number is not known ahead, mapped onto [0, 1) so that the sum only grows: stage n
// (from 1) fills [1 - 2^-(n-1), 1 - 2^-n). `fraction` of stage n done gives this. A child Progress
// (below) reports its brick's stages so; front ends map a run's stages onto a bar the same way.
double stage_series_fraction(int n, double fraction);

struct ProgressUpdate {
  Stage stage = Stage::Extract;
  std::int64_t brick = 0;  // 0-based brick of `bricks`; 0 of 1 outside the tiler
  std::int64_t bricks = 1;
  double fraction = 0;  // of this stage's work in this brick, 0 to 1
};

// Returns whether to go on. Called one call at a time, from whichever thread advanced the work.
using ProgressCallback = std::function<bool(const ProgressUpdate&)>;

// Told, one line at a time and without the "isotile: warning: " that stderr gets, what a run
// does other than it was asked while its result stays right: auto's fall back to the CPU after a
// GPU backend failed (ExtractOptions::warn), a memory budget the surface overflows
// (TiledOptions::warn). Front ends route it to their own channel (the MeshLab plugin's log,
// Python's warnings). Called from the thread that found it, at most a few times a run.
using Warn = std::function<void(const std::string&)>;

// `line` to `to`, or where `to` is null to stderr as "isotile: warning: LINE", so that a caller
// that set nothing still hears it.
void say_warning(const Warn& to, const std::string& line);

// Thrown out of the library when a progress callback (or cancel()) asked to stop.
struct Cancelled : Error {
  Cancelled() : Error("cancelled") {}
};

class Progress {
 public:
  Progress() = default;  // nobody listens; cancel() still works
  explicit Progress(ProgressCallback callback) : callback_(std::move(callback)) {}
  // Reports to `parent` as brick `brick` of `bricks` of its `stage` (see Nesting above).
  Progress(Progress& parent, Stage stage, std::int64_t brick, std::int64_t bricks);
  // Reports its stages to `parent` as the share [from, to] of the parent's (see Shares above).
  Progress(Progress& parent, double from, double to);
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // The brick the following stages work on (the tiler sets it; it stays until set again).
  void set_brick(std::int64_t brick, std::int64_t bricks);
  // Starts `stage` of `total` units in the current brick and tells the callback (fraction 0).
  // Throws Cancelled when the run is cancelled.
  void begin(Stage stage, std::int64_t total);
  // Records `units` more of the current stage done (any thread) and tells the callback. Throws
  // Cancelled when the run is cancelled.
  void advance(std::int64_t units = 1);
  // Throws Cancelled when the run is cancelled; for loops between advance() calls.
  void check() const {
    if (cancelled()) throw Cancelled();
  }
  // A child's brick is done: tells the parent fraction 1 of its stage for the brick. Throws
  // Cancelled when the run is cancelled. On a root Progress: advance() to the end of the stage.
  void finish();
  bool cancelled() const {
    return cancelled_.load(std::memory_order_relaxed) || (parent_ && parent_->cancelled());
  }
  // Cancels the run from outside the callback (another thread; a signal handler: the flag is a
  // lock-free atomic).
  void cancel() { cancelled_.store(true, std::memory_order_relaxed); }
  // A second reason to stop, asked after the callback at every report of this Progress and its
  // children: true cancels the run as a false from the callback would, and the one who set it
  // says why (the pipeline ends a volume's read early when the GL backend it will need failed to
  // start meanwhile). Called one call at a time, from whichever thread reports; whoever sets it
  // clears it (an empty function) when the work it watches ends.
  void set_stop_when(std::function<bool()> stop);

 private:
  void report(const ProgressUpdate& update);       // calls the callback (a child: the parent's)
  void report_root(const ProgressUpdate& update);  // a root's callback, under callback_mutex_

  ProgressCallback callback_;
  std::function<bool()> stop_when_;  // a root's, under callback_mutex_
  Progress* parent_ = nullptr;       // a child's parent
  Stage parent_stage_ = Stage::Extract;
  int child_stages_ = 0;       // a child's begin() calls so far
  double child_reported_ = 0;  // the highest fraction a child told its parent
  bool share_ = false;         // a share of its parent's stage, from share_from_ to share_to_
  double share_from_ = 0, share_to_ = 1;
  std::mutex mutex_;           // the stage's state
  std::mutex callback_mutex_;  // one callback at a time (taken after a child's or own mutex_)
  Stage stage_ = Stage::Read;
  std::int64_t total_ = 1, done_ = 0, brick_ = 0, bricks_ = 1;
  std::atomic<bool> cancelled_{false};
  static_assert(std::atomic<bool>::is_always_lock_free);
};

// For loops handed a Progress* that may be null.
inline void progress_begin(Progress* p, Stage stage, std::int64_t total) {
  if (p) p->begin(stage, total);
}
inline void progress_advance(Progress* p, std::int64_t units = 1) {
  if (p) p->advance(units);
}
inline void progress_check(const Progress* p) {
  if (p) p->check();
}

// A child Progress of `parent` (see Nesting above), or none when `parent` is null.
class ChildProgress {
 public:
  ChildProgress(Progress* parent, Stage stage, std::int64_t brick, std::int64_t bricks) {
    if (parent) child_.emplace(*parent, stage, brick, bricks);
  }
  Progress* get() { return child_ ? &*child_ : nullptr; }

 private:
  std::optional<Progress> child_;
};

// Wraps the body of a tbb::parallel_for over a blocked_range of items (rows): with a Progress,
// each range is cut into pieces of at most `unit` items, each piece checked for cancel before
// and advanced after (`unit` items: well under 0.1 s on one thread; a z-slice of rows). Without
// one, the body runs on the whole range as before. The Progress's stage counts the items.
template <class Body>
auto for_units(Progress* p, std::int64_t unit, Body&& body) {
  return [p, unit, &body](const auto& range) {
    if (!p) return body(range);
    using Range = std::decay_t<decltype(range)>;
    using Value = std::decay_t<decltype(range.begin())>;
    const auto step = static_cast<Value>(std::max<std::int64_t>(unit, 1));
    for (Value lo = range.begin(); lo < range.end();) {
      p->check();
      const Value hi = range.end() - lo > step ? lo + step : range.end();
      body(Range(lo, hi));
      p->advance(static_cast<std::int64_t>(hi - lo));
      lo = hi;
    }
  };
}

}  // namespace isotile
