#include "core/progress.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

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
    case Stage::SimplifySeams:
      return "simplify seams";
    case Stage::Write:
      return "write";
  }
  return "?";
}

double stage_series_fraction(int n, double fraction) {
  return 1 - std::ldexp(1.0, 1 - n) + std::ldexp(1.0, -n) * fraction;
}

void say_warning(const Warn& to, const std::string& line) {
  if (to)
    to(line);
  else
    std::fprintf(stderr, "isotile: warning: %s\n", line.c_str());
}

Progress::Progress(Progress& parent, Stage stage, std::int64_t brick, std::int64_t bricks)
    : parent_(&parent), parent_stage_(stage), brick_(brick), bricks_(bricks > 0 ? bricks : 1) {}

Progress::Progress(Progress& parent, double from, double to)
    : parent_(&parent), share_(true), share_from_(from), share_to_(to) {}

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
  if (parent_) ++child_stages_;
  report({stage_, brick_, bricks_, 0.0});
}

void Progress::finish() {
  check();
  std::lock_guard lock(mutex_);
  if (!parent_ || share_) {
    done_ = total_;
    report({stage_, brick_, bricks_, 1.0});
    return;
  }
  child_reported_ = 1;
  parent_->report_root({parent_stage_, brick_, bricks_, 1.0});
}

void Progress::advance(std::int64_t units) {
  check();
  std::lock_guard lock(mutex_);
  done_ = std::min(total_, done_ + units);
  report({stage_, brick_, bricks_, static_cast<double>(done_) / static_cast<double>(total_)});
}

void Progress::report(const ProgressUpdate& update) {
  if (!parent_) return report_root(update);
  if (share_) {
    // As the parent's own report (under the parent's mutex_, taken after this one's): a brick's
    // child maps it into its brick's series as it would its own stage.
    std::lock_guard lock(parent_->mutex_);
    parent_->report({update.stage, parent_->brick_, parent_->bricks_,
                     share_from_ + (share_to_ - share_from_) * update.fraction});
    return;
  }
  // A child (under its own mutex_): its stages are a series (stage_series_fraction), so the
  // brick's fraction grows through any number of them and stays below 1 until finish().
  const int n = std::max(child_stages_, 1);
  child_reported_ = std::max(child_reported_, std::min(stage_series_fraction(n, update.fraction),
                                                       1 - std::ldexp(1.0, -n) / 2));
  parent_->report_root({parent_stage_, brick_, bricks_, child_reported_});
  check();
}

void Progress::report_root(const ProgressUpdate& update) {
  if (parent_) return parent_->report_root(update);
  {
    // Under callback_mutex_: the callback is called one call at a time (from any thread, children's
    // included), and a false answer is seen by every thread before its next unit of work.
    std::lock_guard lock(callback_mutex_);
    if ((callback_ && !callback_(update)) || (stop_when_ && stop_when_())) cancel();
  }
  check();
}

void Progress::set_stop_when(std::function<bool()> stop) {
  if (parent_) return parent_->set_stop_when(std::move(stop));
  std::lock_guard lock(callback_mutex_);
  stop_when_ = std::move(stop);
}

}  // namespace isotile
