#include "stage_clock.h"

#include <glad/gl.h>

#include <algorithm>

#include "gl_context.h"

namespace isotile::gl {

const char* gl_stage_name(GlStage s) {
  static constexpr const char* kNames[kGlStageCount] = {"upload",   "prepare", "classify", "scan",
                                                        "vertices", "faces",   "readback"};
  return kNames[static_cast<int>(s)];
}

StageClock::~StageClock() {
  if (!queries_.empty()) glDeleteQueries(static_cast<GLsizei>(queries_.size()), queries_.data());
}

StageClock::Mark StageClock::device_mark() {
  if (used_ == queries_.size()) {
    // Query objects in batches, reused by every round of marks until the clock goes: no
    // glGenQueries per mark. The first batch also decides the flush below.
    if (queries_.empty()) flush_marks_ = device().software;
    const std::size_t more = std::max<std::size_t>(32, queries_.size());
    queries_.resize(used_ + more);
    glGenQueries(static_cast<GLsizei>(more), queries_.data() + used_);
  }
  glQueryCounter(queries_[used_], GL_TIMESTAMP);
  // The GL records a timestamp once the commands before it have completed, in stream order, so
  // a hardware driver needs no flush here (one would cost a submission per mark, several per
  // slab). llvmpipe records it only when the commands before it are flushed: without a flush a
  // mark would read as a later stage's end. A flush does not wait for the device.
  if (flush_marks_) glFlush();
  return {true, static_cast<std::int64_t>(used_++)};
}

StageClock::Mark StageClock::cpu_mark() {
  GLint64 t = 0;
  glGetInteger64v(GL_TIMESTAMP, &t);
  return {false, static_cast<std::int64_t>(t)};
}

void StageClock::add(GlStage s, Mark from, Mark to) {
  spans_.push_back({s, from, to});
}

void StageClock::add_wait(GlStage s, Mark done, Mark before, Mark after) {
  spans_.push_back({s, done, after, before, true});
}

std::int64_t StageClock::value(Mark m) {
  if (!m.query) return m.value;
  GLuint64 t = 0;
  glGetQueryObjectui64v(queries_[static_cast<std::size_t>(m.value)], GL_QUERY_RESULT, &t);
  return static_cast<std::int64_t>(t);
}

const GlTimes& StageClock::collect() {
  for (const Span& s : spans_) {
    const std::int64_t to = value(s.to);
    std::int64_t from = value(s.from);
    if (s.clamp) from = std::clamp(from, value(s.before), to);
    const std::int64_t ns = to - from;
    if (ns > 0) times_[s.stage] += static_cast<double>(ns) * 1e-9;
  }
  spans_.clear();
  used_ = 0;  // the query objects are kept for the next round's marks
  return times_;
}

}  // namespace isotile::gl
