// A thread of its own for a pipeline's extractions, holding the backend ready (hold_backend())
// from its start to its end.
//
// The tiler's pipeline extracts its bricks one at a time but on whichever TBB thread runs the
// stage, so no thread could hold the GL context across the bricks: each brick took it and gave it
// back, about 0.2 s a time on the H200 (docs/gl.md). The stage hands each brick's extraction to
// the lane instead and waits for it; the lane's thread keeps the context current for the whole
// pass. With the CPU backend (nothing to hold) no thread is started and run() calls the job in
// place.
#pragma once

#include <condition_variable>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <type_traits>
#include <utility>

#include "core/extract/extract.h"

namespace isotile {

class BackendLane {
 public:
  // Starts the thread where the backend that extractions with `options` run on has something to
  // hold (Auto: the one it chooses). Where holding it fails (no context) the lane runs its jobs
  // without, and they meet the backend's own error.
  explicit BackendLane(const ExtractOptions& options);
  // Ends the hold on the lane's thread and joins it.
  ~BackendLane();
  BackendLane(const BackendLane&) = delete;
  BackendLane& operator=(const BackendLane&) = delete;

  // Runs `job` on the lane (in place without one), waits for it and returns its result or
  // rethrows its exception. Calls from several threads are run one at a time.
  template <class Job>
  auto run(Job&& job) -> std::invoke_result_t<Job&> {
    using R = std::invoke_result_t<Job&>;
    if (!thread_.joinable()) return job();
    std::exception_ptr error;
    if constexpr (std::is_void_v<R>) {
      run_on_lane([&] {
        try {
          job();
        } catch (...) {
          error = std::current_exception();
        }
      });
      if (error) std::rethrow_exception(error);
    } else {
      std::optional<R> result;
      run_on_lane([&] {
        try {
          result.emplace(job());
        } catch (...) {
          error = std::current_exception();
        }
      });
      if (error) std::rethrow_exception(error);
      return std::move(*result);
    }
  }

  // Whether jobs run on a thread of the lane's own.
  bool threaded() const { return thread_.joinable(); }

 private:
  void run_on_lane(const std::function<void()>& job);
  void serve(Backend backend);

  std::mutex mutex_;
  std::condition_variable changed_;
  const std::function<void()>* job_ = nullptr;  // the job handed over, until it has run
  bool stop_ = false;
  std::mutex callers_;  // one run() at a time
  std::thread thread_;
};

}  // namespace isotile
