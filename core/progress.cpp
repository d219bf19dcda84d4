#include "core/progress.h"

#include <algorithm>

namespace isotile {

std::string_view stage_name(Stage stage) {
  switch (stage) {
    case Stage::Read:
      return "read";
    case Stage::Histogram:
      return "histogram";
    case Stage::Count:
      return "count";
    case Stage::Extract:
      return "extract";
    case Stage::MacetSearch:
      return "macet search";
    case Stage::Simplify:
      return "simplify";
    case Stage::Write:
      return "write";
  }
  return "?";
}

void Progress::set_brick(std::int64_t brick, std::int64_t bricks) {
  std::lock_guard lock(mutex_);
  brick_ = brick;
  bricks_ = bricks > 0 ? bricks : 1;
}

void Progress::begin(Stage stage, std::int64_t total) {
  check();
  std::lock_guard lock(mutex_);
  stage_ = stage;
  total_ = total > 0 ? total : 1;
  done_ = 0;
  report({stage_, brick_, bricks_, 0.0});
}

void Progress::advance(std::int64_t units) {
  check();
  std::lock_guard lock(mutex_);
  done_ = std::min(total_, done_ + units);
  report({stage_, brick_, bricks_, static_cast<double>(done_) / static_cast<double>(total_)});
}

void Progress::report(const ProgressUpdate& update) {
  // Under mutex_: the callback is called one call at a time, and a false answer is seen by every
  // thread before its next unit of work.
  if (callback_ && !callback_(update)) cancel();
  check();
}

}  // namespace isotile
