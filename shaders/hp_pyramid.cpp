#include "hp_pyramid.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <string>

#include "core/errors.h"
#include "gl_context.h"

namespace isotile::gl {

namespace {

// One invocation per node of `level`, in workgroups of 256 (each covers 32 and 4 of the nodes
// of the two levels above).
std::uint64_t invocations_over(const Pyramid& pyr, int level) {
  return (std::uint64_t{pyr.count[level]} + 255) / 256 * 256;
}

int checked(int per_pass) {
  if (per_pass == 0) return default_levels_per_pass();
  if (per_pass < 1 || per_pass > kMaxLevelsPerPass)
    throw Error("levels per HistoPyramid pass must be 1 to " + std::to_string(kMaxLevelsPerPass));
  return per_pass;
}

}  // namespace

int default_levels_per_pass() {
  // ISOTILE_HP_LEVELS_PER_PASS overrides the device's choice (a GPU's A/B, and the tests that run
  // the hardware devices' passes on llvmpipe).
  if (const char* env = std::getenv("ISOTILE_HP_LEVELS_PER_PASS"); env && *env) {
    const std::string v = env;
    if (v.size() != 1 || v[0] < '1' || v[0] > '0' + kMaxLevelsPerPass)
      throw InputError("ISOTILE_HP_LEVELS_PER_PASS is '" + v + "': it must be 1 to " +
                       std::to_string(kMaxLevelsPerPass));
    return v[0] - '0';
  }
  // Measured on llvmpipe (bench_backends' scan stage, docs/gl.md): three levels per pass, whose
  // shader holds barriers, took 2.3-2.8x as long as one level per pass without them.
  return device().software ? 1 : kMaxLevelsPerPass;
}

std::string pyramid_pass_defines(const std::string& defines, int per_pass, bool base,
                                 bool face_offsets) {
  std::string d = defines;  // appended, not concatenated: GCC 12's -Wrestrict
  if (base) d += "#define BASE\n";
  if (checked(per_pass) == 1) d += "#define ONE_LEVEL_PER_PASS\n";
  if (face_offsets) d += "#define FACE_OFFSETS\n";
  return d;
}

namespace {
std::atomic<int> g_output{-1};  // set_hp_output()'s choice, -1: none
}  // namespace

void set_hp_output(std::optional<HpOutput> output) {
  g_output = output ? static_cast<int>(*output) : -1;
}

HpOutput default_hp_output() {
  if (const int chosen = g_output.load(); chosen >= 0) return static_cast<HpOutput>(chosen);
  const char* env = std::getenv("ISOTILE_HP_OUTPUT");
  if (!env || !*env) return HpOutput::Descend;
  const std::string v = env;
  if (v == "descend") return HpOutput::Descend;
  if (v == "scatter") return HpOutput::Scatter;
  throw InputError("ISOTILE_HP_OUTPUT is '" + v + "': it must be descend or scatter");
}

std::string output_pass_defines(const std::string& defines, HpOutput output) {
  std::string d = defines;
  if (output == HpOutput::Scatter) d += "#define SCATTER_OUTPUT\n#define FACE_OFFSETS\n";
  return d;
}

int reduce_levels(const Pyramid& pyr, const std::string& defines, int per_pass) {
  per_pass = checked(per_pass);
  const GLuint base = program({{GL_COMPUTE_SHADER, "hp_reduce.comp"}},
                              pyramid_pass_defines(defines, per_pass, true));
  const GLuint upper =
      program({{GL_COMPUTE_SHADER, "hp_reduce.comp"}}, pyramid_pass_defines(defines, per_pass));
  int passes = 0;
  // Bottom-up: each pass reads level `src` and writes the `steps` levels above it.
  for (int src = 0; src < pyr.levels; src += per_pass) {
    const int steps = std::min(per_pass, pyr.levels - src);
    const GLuint prog = src == 0 ? base : upper;
    pyr.set_uniforms(prog);
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_src_level"), src);
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_steps"), steps);
    glUseProgram(prog);
    dispatch(invocations_over(pyr, src + 1));
    ++passes;
  }
  return passes;
}

int sweep_offsets(const Pyramid& pyr, const std::string& defines, const Buffer& offsets,
                  int per_pass, bool face_offsets) {
  per_pass = checked(per_pass);
  const GLuint prog = program({{GL_COMPUTE_SHADER, "hp_downsweep.comp"}},
                              pyramid_pass_defines(defines, per_pass, false, face_offsets));
  // The top node has no vertices (or faces) before it; a clear is ordered before the dispatches
  // that read it like any other command.
  const std::uint32_t zero = 0;
  for (int kind = 0; kind < (face_offsets ? 2 : 1); ++kind)
    glClearNamedBufferSubData(offsets.id(), GL_R32UI,
                              (kind * pyr.nodes + pyr.offset[pyr.levels]) * 4, 4, GL_RED_INTEGER,
                              GL_UNSIGNED_INT, &zero);
  pyr.set_uniforms(prog);
  glUseProgram(prog);
  int passes = 0;
  // Top-down: each pass writes the `steps` levels below level `top`, whose offsets are known.
  for (int top = pyr.levels; top > 1; top -= per_pass) {
    const int steps = std::min(per_pass, top - 1);
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_bottom"), top - steps);
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_steps"), steps);
    dispatch(invocations_over(pyr, top - steps));
    ++passes;
  }
  return passes;
}

}  // namespace isotile::gl
