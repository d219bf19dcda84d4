// The HistoPyramid's count pyramid as both HistoPyramid extractors lay it out (mc_histopyramid.cpp
// describes it): levels of nodes summing eight consecutive nodes of the level below.
#pragma once

#include <glad/gl.h>

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "gl_program.h"

namespace isotile::gl {

inline constexpr int kMaxPyramidLevels = 16;
// Levels one dispatch of hp_reduce.comp or hp_downsweep.comp writes at most: a workgroup's 256
// invocations compute 256 nodes of the lowest level it writes, and pass them through shared
// memory to their 32 parents and 4 grandparents.
inline constexpr int kMaxLevelsPerPass = 3;

inline void set_uniform_u(GLuint prog, const char* name, std::uint32_t v) {
  glProgramUniform1ui(prog, glGetUniformLocation(prog, name), v);
}

struct Pyramid {
  int levels = 0;                                         // L; level L is the single top node
  std::array<std::uint32_t, kMaxPyramidLevels> count{};   // nodes per level (level 0: elements)
  std::array<std::uint32_t, kMaxPyramidLevels> offset{};  // start of level l >= 1 in the buffer
  std::uint64_t nodes = 0;                                // levels 1..L together

  explicit Pyramid(std::uint64_t elements) {
    count[0] = static_cast<std::uint32_t>(elements);
    std::uint64_t n = elements;
    do {
      n = (n + 7) / 8;
      ++levels;
      count[levels] = static_cast<std::uint32_t>(n);
      offset[levels] = static_cast<std::uint32_t>(nodes);
      nodes += n;
    } while (n > 1);
  }

  void set_uniforms(GLuint prog) const {
    glProgramUniform1i(prog, glGetUniformLocation(prog, "u_levels"), levels);
    glProgramUniform1uiv(prog, glGetUniformLocation(prog, "u_level_offset"), kMaxPyramidLevels,
                         offset.data());
    glProgramUniform1uiv(prog, glGetUniformLocation(prog, "u_level_count"), kMaxPyramidLevels,
                         count.data());
  }
};

// Pyramid levels per dispatch on the current device: one on a software rasteriser, where the
// shared memory and barriers that carry a pass's sums (and offsets) from level to level cost
// more than the dispatches they save (llvmpipe: docs/gl.md), else kMaxLevelsPerPass.
int default_levels_per_pass();

// Levels 1..L of `pyr`'s count pyramid from the element codes (bound at 1; the pyramid at 2),
// `per_pass` levels per dispatch (1..kMaxLevelsPerPass; 0: default_levels_per_pass()), with
// hp_reduce.comp built from `defines` (the samples' and the method's pyramid defines). Returns
// the number of dispatches.
int reduce_levels(const Pyramid& pyr, const std::string& defines, int per_pass = 0);

// The vertex offset of every node of levels 1..L (in `offsets`, bound at 5; the pyramid at 2),
// top-down, the top node's being zero, `per_pass` levels per dispatch as above, with
// hp_downsweep.comp built from `defines`; with `face_offsets`, the faces' offsets too, after the
// vertices' (`offsets` then holds 2 * pyr.nodes words). Returns the number of dispatches.
int sweep_offsets(const Pyramid& pyr, const std::string& defines, const Buffer& offsets,
                  int per_pass = 0, bool face_offsets = false);

// The defines of hp_reduce.comp (with BASE: the level above the elements) and
// hp_downsweep.comp (with `face_offsets`: the faces' too) for `per_pass` levels per dispatch.
std::string pyramid_pass_defines(const std::string& defines, int per_pass, bool base = false,
                                 bool face_offsets = false);

// How the output passes find their outputs' elements (hp_output.glsl). Both write the same
// outputs in the same order.
enum class HpOutput {
  Descend,  // one invocation per output, descending the pyramid from the top to its element
  Scatter,  // one invocation per element, writing its outputs from the offsets' down-sweep
};
// Descend, unless ISOTILE_HP_OUTPUT says `scatter` (anything but `descend` or `scatter` is an
// InputError naming the variable) or set_hp_output() chose. Which is faster is a GPU's to say
// (bench_backends' "hpe" column, bench_hp_layouts' compact one; docs/gl.md): until one has, the
// descent stays the default.
HpOutput default_hp_output();
// Chooses the output design for the process's later extractions over the environment's
// (std::nullopt: the environment's again); for benchmarks that time both in one run.
void set_hp_output(std::optional<HpOutput> output);
// The output passes' defines for `output` (Scatter: SCATTER_OUTPUT and FACE_OFFSETS).
std::string output_pass_defines(const std::string& defines, HpOutput output);

// What hp_prefix.comp (`prog`, its other uniforms already set) counts before `element`: the
// vertices of the elements before it, with the pyramid bound as for the output passes. Both
// HistoPyramid extractors use it to find the vertices a slab shares with the next one.
inline std::uint32_t vertices_before(GLuint prog, const Pyramid& pyr, std::uint32_t element) {
  pyr.set_uniforms(prog);
  set_uniform_u(prog, "u_element", element);
  const Buffer result(4);
  result.bind(GL_SHADER_STORAGE_BUFFER, 3);
  glUseProgram(prog);
  dispatch(1);
  std::uint32_t before = 0;
  result.read(0, 4, &before);
  return before;
}

}  // namespace isotile::gl
