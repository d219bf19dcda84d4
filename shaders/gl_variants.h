// Every GLSL program the GL extractors can build, as data: for each method, path, sample type and
// option that changes a program's defines, the stages and defines exactly as the drivers pass them
// to program(). tests/test_glsl_variants.cpp runs glslang over each (no GPU needed), and the GL
// tests check that every program they built is listed here, so the list cannot fall behind the
// drivers.
#pragma once

#include <string>
#include <vector>

#include "gl_program.h"

namespace isotile::gl {

struct ProgramVariant {
  std::string what;  // e.g. "macet hp vertices, double samples, normals"
  std::vector<Stage> stages;
  std::string defines;
  std::vector<std::string> varyings;  // transform feedback, geometry-shader paths
};

// The stages of `isotile render`'s program (mesh_render.cpp).
std::vector<Stage> render_stages();

// Sorted by key, one entry per distinct program_key().
std::vector<ProgramVariant> program_variants();

}  // namespace isotile::gl
