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
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string_view>

#include "core/errors.h"

namespace isotile {

// The stages of a run, in the order a run usually meets them.
enum class Stage { Read, Histogram, Count, Extract, MacetSearch, Simplify, Write };
std::string_view stage_name(Stage stage);  // "read", "histogram", "count", "extract", ...

struct ProgressUpdate {
  Stage stage = Stage::Extract;
  std::int64_t brick = 0;  // 0-based brick of `bricks`; 0 of 1 outside the tiler
  std::int64_t bricks = 1;
  double fraction = 0;  // of this stage's work in this brick, 0 to 1
};

// Returns whether to go on. Called one call at a time, from whichever thread advanced the work.
using ProgressCallback = std::function<bool(const ProgressUpdate&)>;

// Thrown out of the library when a progress callback (or cancel()) asked to stop.
struct Cancelled : Error {
  Cancelled() : Error("cancelled") {}
};

class Progress {
 public:
  Progress() = default;  // nobody listens; cancel() still works
  explicit Progress(ProgressCallback callback) : callback_(std::move(callback)) {}
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
  bool cancelled() const { return cancelled_.load(std::memory_order_relaxed); }
  // Cancels the run from outside the callback (another thread; a signal handler: the flag is a
  // lock-free atomic).
  void cancel() { cancelled_.store(true, std::memory_order_relaxed); }

 private:
  void report(const ProgressUpdate& update);  // calls the callback under mutex_

  ProgressCallback callback_;
  std::mutex mutex_;
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

}  // namespace isotile
