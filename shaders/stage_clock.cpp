#include "stage_clock.h"

#include <glad/gl.h>

#include <algorithm>

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
  GLuint q = 0;
  glGenQueries(1, &q);
  glQueryCounter(q, GL_TIMESTAMP);
  // Submitted now, not at the driver's next flush: llvmpipe records a timestamp when the
  // commands before it are flushed, so without this a mark would read as a later stage's end.
  // A flush does not wait for the device.
  glFlush();
  queries_.push_back(q);
  return {true, static_cast<std::int64_t>(queries_.size() - 1)};
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
  if (!queries_.empty()) glDeleteQueries(static_cast<GLsizei>(queries_.size()), queries_.data());
  queries_.clear();
  return times_;
}

}  // namespace isotile::gl
