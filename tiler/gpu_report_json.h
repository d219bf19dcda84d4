// The GL backends' report of one extraction (core's GpuReport) in `isotile extract --stats`
// (docs/cli.md): `seconds.gl` (per stage, and the context's start-up), `upload_bytes`,
// `upload_gbps` and `gl_program_cache`; where the CPU made the mesh, no `seconds.gl` and the
// others null.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>

#include "core/extract/extract.h"

namespace isotile {

inline void add_gpu_report(nlohmann::ordered_json& stats, const std::optional<GpuReport>& gpu) {
  using json = nlohmann::ordered_json;
  if (!gpu) {
    // No seconds.gl (rather than null): scripts read the entries of `seconds` as numbers, or as
    // an object of numbers (`stages`, `gl`) where present.
    stats["upload_bytes"] = nullptr;
    stats["upload_gbps"] = nullptr;
    stats["gl_program_cache"] = nullptr;
    return;
  }
  json gl = json::object();
  for (const auto& [stage, seconds] : gpu->seconds) gl[stage] = seconds;
  gl["context"] = gpu->context_seconds;
  if (!stats.contains("seconds")) stats["seconds"] = json::object();
  stats["seconds"]["gl"] = gl;
  stats["upload_bytes"] = gpu->upload_bytes;
  stats["upload_gbps"] =
      gpu->upload_seconds > 0
          ? json(static_cast<double>(gpu->upload_bytes) / gpu->upload_seconds / 1e9)
          : json(nullptr);
  const char* state = !gpu->program_cache_off.empty() ? "off"
                      : gpu->programs_compiled == 0   ? "hit"
                      : gpu->programs_loaded == 0     ? "miss"
                                                      : "partial";
  json cache = {{"state", state},
                {"loaded", gpu->programs_loaded},
                {"compiled", gpu->programs_compiled},
                {"rejected", gpu->programs_rejected}};
  if (!gpu->program_cache_off.empty()) cache["off_because"] = gpu->program_cache_off;
  stats["gl_program_cache"] = cache;
}

}  // namespace isotile
