#include "tiler/backend_lane.h"

namespace isotile {

BackendLane::BackendLane(const ExtractOptions& options) {
  Backend backend = options.backend;
  if (backend == Backend::Auto) {
    try {
      backend = choose_backend(options).backend;
    } catch (const std::exception&) {
      return;  // the extractions say why
    }
  }
  if (backend_holds(backend)) thread_ = std::thread([this, backend] { serve(backend); });
}

BackendLane::~BackendLane() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  thread_.join();
}

void BackendLane::serve(Backend backend) {
  std::shared_ptr<void> hold;
  try {
    hold = hold_backend(backend);
  } catch (const std::exception&) {
    // No context: the jobs run without the hold and meet the backend's own error.
  }
  std::unique_lock lock(mutex_);
  for (;;) {
    changed_.wait(lock, [&] { return stop_ || job_; });
    if (!job_) break;  // stopped, nothing left to run
    const std::function<void()>* job = job_;
    lock.unlock();
    (*job)();  // run() catches what the job throws
    lock.lock();
    job_ = nullptr;  // done
    changed_.notify_all();
  }
  lock.unlock();
  hold.reset();  // given back on the thread that took it
}

void BackendLane::run_on_lane(const std::function<void()>& job) {
  std::lock_guard one(callers_);
  std::unique_lock lock(mutex_);
  job_ = &job;
  changed_.notify_all();
  changed_.wait(lock, [&] { return !job_; });
}

}  // namespace isotile
