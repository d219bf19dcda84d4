// Per-stage device times from GL timer queries (GL_TIMESTAMP query objects), with no glFinish:
// marks are queries issued into the command stream, or the GL clock read on the CPU
// (glGetInteger64v(GL_TIMESTAMP), the time the commands issued so far reached the device), and
// a stage's time is the difference of two marks on that one clock. The results are read when the
// run collects them (collect()), after its read-backs have waited for the device anyway.
// Call only inside a gl::Scope (GlTimes alone needs no GL).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace isotile::gl {

// The stages of the GL drivers, as `isotile extract --stats` names them (docs/cli.md).
enum class GlStage {
  Upload,    // samples handed to GL until resident on the device
  Prepare,   // a method's own passes before classification (Macet's displaced vertices)
  Classify,  // classification / counting (HistoPyramid: codes; geometry shader: the draws)
  Scan,      // the count pyramid, its offsets and the totals
  Vertices,  // the vertex pass
  Faces,     // the face pass
  Readback,  // copies of results from the device to the CPU
};
inline constexpr int kGlStageCount = 7;
const char* gl_stage_name(GlStage s);  // "upload", "prepare", "classify", ...

// Seconds per stage, summed over slabs, and the upload's bytes.
struct GlTimes {
  std::array<double, kGlStageCount> seconds{};
  std::uint64_t upload_bytes = 0;
  double& operator[](GlStage s) { return seconds[static_cast<int>(s)]; }
  double operator[](GlStage s) const { return seconds[static_cast<int>(s)]; }
};

class StageClock {
 public:
  struct Mark {
    bool query = false;
    std::int64_t value = 0;  // query: index into queries_; else nanoseconds on the GL clock
  };

  StageClock() = default;
  ~StageClock();
  StageClock(const StageClock&) = delete;
  StageClock& operator=(const StageClock&) = delete;

  // When the commands issued so far have completed on the device (a GL_TIMESTAMP query; its
  // query object is reused after collect()).
  Mark device_mark();
  // Now on the GL clock, as the CPU sees it (no wait).
  static Mark cpu_mark();
  // Adds the time from `from` to `to` to stage `s` (resolved by collect()).
  void add(GlStage s, Mark from, Mark to);
  // Adds the time of a copy to the CPU that waited for the device: from when the device finished
  // (`done`, a device mark) or the copy began (`before`), whichever is later, until `after` (both
  // CPU marks). A device mark outside [before, after] (drivers that record timestamps late, as
  // llvmpipe may) falls back to the CPU's.
  void add_wait(GlStage s, Mark done, Mark before, Mark after);
  void add_upload_bytes(std::uint64_t bytes) { times_.upload_bytes += bytes; }
  // Reads every query (waiting for the device where it has not finished) and returns the sums so
  // far; the clock can go on being used.
  const GlTimes& collect();

 private:
  std::int64_t value(Mark m);
  struct Span {
    GlStage stage;
    Mark from, to;
    Mark before{};  // add_wait(): `from` is clamped to [before, to]
    bool clamp = false;
  };
  std::vector<unsigned> queries_;  // GLuint; generated in batches, reused after collect()
  std::size_t used_ = 0;           // queries_[0, used_) hold this round's marks
  bool flush_marks_ = false;       // software rasterisers: flush after each mark (device_mark())
  std::vector<Span> spans_;
  GlTimes times_;
};

// The marks of an optional clock: a default Mark without one (the stages not asked for), so that
// the drivers mark unconditionally and add spans only `if (clock)`.
inline StageClock::Mark device_mark(StageClock* clock) {
  return clock ? clock->device_mark() : StageClock::Mark{};
}
inline StageClock::Mark cpu_mark(StageClock* clock) {
  return clock ? StageClock::cpu_mark() : StageClock::Mark{};
}

}  // namespace isotile::gl
