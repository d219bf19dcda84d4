// `isotile gl-info [--json]`: the OpenGL device the gs and hp backends would use.
#include "tiler/cli/commands.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <vector>

#include "core/errors.h"
#include "core/extract/extract.h"
#include "tiler/stats_json.h"
#ifdef ISOTILE_HAVE_GL
#include "shaders/gl_backends.h"
#include "shaders/gl_context.h"
#endif

namespace isotile::cli {

using json = StatsJson;

CLI::App* add_gl_info_command(CLI::App& app, bool& json_flag) {
  auto* gl_info_cmd = app.add_subcommand(
      "gl-info", "Describe the OpenGL device the gs and hp backends would use, and its limits");
  gl_info_cmd->add_flag("--json", json_flag, "Print JSON");
  return gl_info_cmd;
}

int run_gl_info(bool as_json) {
#ifdef ISOTILE_HAVE_GL
  const isotile::gl::DeviceInfo& d = isotile::gl::device();  // InputError when there is none
  json j;
  j["platform"] = d.platform;
  // Which GPU of how many, and why that one (ISOTILE_GL_DEVICE, the launcher's node-local rank).
  j["egl_device"] = d.device_index < 0
                        ? json(nullptr)
                        : json(std::to_string(d.device_index) + " of " +
                               std::to_string(d.device_count) + " (" + d.device_chosen_by + ")");
  j["vendor"] = d.vendor;
  j["renderer"] = d.renderer;
  j["version"] = d.version;
  j["glsl_version"] = d.glsl_version;
  j["software"] = d.software;
  // null where the driver does not say (no NVX or ATI memory query: llvmpipe), not its -1.
  const auto kib = [](auto v) { return v >= 0 ? json(v) : json(nullptr); };
  j["memory_total_kib"] = kib(d.memory_total_kib);
  j["memory_free_kib"] = kib(d.memory_free_kib);
  j["max_shader_storage_block_bytes"] = d.max_ssbo_bytes;
  j["max_compute_work_group_count"] = d.max_compute_groups;
  j["max_geometry_output_vertices"] = d.max_gs_output_vertices;
  j["max_transform_feedback_interleaved_components"] = d.max_tf_interleaved;
  j["max_vertex_shader_storage_blocks"] = d.max_vertex_ssbo_blocks;
  j["max_geometry_shader_storage_blocks"] = d.max_geometry_ssbo_blocks;
  j["max_3d_texture_size"] = d.max_3d_texture;
  j["program_binary_formats"] = d.program_binary_formats;
  const isotile::gl::ProgramCacheState cache = isotile::gl::program_cache_state();
  j["program_cache"] = cache.enabled
                           ? json(cache.folder)
                           : json("off: " + cache.off_because +
                                  (cache.folder.empty() ? "" : " (" + cache.folder + ")"));
  json backends = json::object();
  for (const BackendCaps& c : capabilities())
    backends[std::string(backend_name(c.backend))] =
        c.available ? (c.hardware ? "available (GPU)" : "available") : c.why_unavailable;
  j["backends"] = backends;
  j["auto"] = backend_name(resolve_backend({}));
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  for (const auto& [key, value] : j.items())
    std::printf("%-46s %s\n", key.c_str(),
                value.is_string() ? value.get<std::string>().c_str() : value.dump().c_str());
  return 0;
#else
  (void)as_json;
  throw InputError("this isotile was built without OpenGL (ISOTILE_GL=OFF)");
#endif
}

}  // namespace isotile::cli
