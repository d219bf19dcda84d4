// Does the GL device round double division and sqrt as the CPU does, and keep `precise` a * b + c
// unfused? GLSL asks only for
// float precision of double `/` and `sqrt` (GLSL 4.50, 4.7.1), and Macet's guards and DC's solvers
// decide on such values, so the GL meshes equal the CPU's bit for bit only where the device
// rounds them correctly (docs/gl.md). This runs one compute pass over random operands, computes
// the same on the CPU, and prints how many results differ and by how many units in the last
// place; exit status 1 when any of those differs. fma() is reported beside them: the shaders call
// none, and llvmpipe's double fma is not fused (so no correctly rounded refinement built on an
// exact fma can be bit-exact there). On llvmpipe every result must agree (a ctest); on a GPU
// it is part of the GPU checks (tests/gpu/run_gpu_checks.sh).
//
//   gl_double_check [COUNT]        (default 1000000 operand triples)
#include <glad/gl.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "core/errors.h"
#include "shaders/gl_context.h"
#include "shaders/gl_program.h"

namespace {

const char* kShader = R"(#version 450 core
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer In { dvec4 operands[]; };
layout(std430, binding = 1) writeonly buffer Out { dvec4 results[]; };
uniform uint u_count;
void main() {
  uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 256u;
  if (i >= u_count) return;
  dvec4 o = operands[i];
  precise double q = o.x / o.y;
  precise double r = sqrt(o.z);
  precise double f = fma(o.x, o.y, o.w);
  precise double p = o.x * o.y + o.w;
  results[i] = dvec4(q, r, f, p);
}
)";

std::int64_t ulps(double a, double b) {
  if (a == b || (std::isnan(a) && std::isnan(b))) return 0;
  std::int64_t ia, ib;
  std::memcpy(&ia, &a, 8);
  std::memcpy(&ib, &b, 8);
  if (ia < 0) ia = INT64_MIN - ia;
  if (ib < 0) ib = INT64_MIN - ib;
  return ia > ib ? ia - ib : ib - ia;
}

}  // namespace

int main(int argc, char** argv) {
  const std::uint64_t n = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 1000000;
  if (n == 0 || n > (std::uint64_t{1} << 24)) {
    std::fprintf(stderr, "gl_double_check: COUNT must be in [1, 2^24]\n");
    return 2;
  }
  try {
    std::vector<double> in(4 * n), out(4 * n);
    std::mt19937_64 rng(20261126);
    // Operands over many binades, both signs for the quotient and fma; sqrt of positives.
    std::uniform_real_distribution<double> mant(1.0, 2.0);
    std::uniform_int_distribution<int> expo(-40, 40), sign(0, 1);
    auto any = [&] { return (sign(rng) ? -1.0 : 1.0) * std::ldexp(mant(rng), expo(rng)); };
    for (std::uint64_t i = 0; i < n; ++i) {
      in[4 * i + 0] = any();
      in[4 * i + 1] = any();
      in[4 * i + 2] = std::ldexp(mant(rng), expo(rng));
      in[4 * i + 3] = any();
    }
    std::string renderer;
    {
      isotile::gl::Scope scope;
      renderer = isotile::gl::device().renderer;
      const GLuint sh = glCreateShader(GL_COMPUTE_SHADER);
      glShaderSource(sh, 1, &kShader, nullptr);
      glCompileShader(sh);
      const GLuint prog = glCreateProgram();
      glAttachShader(prog, sh);
      glLinkProgram(prog);
      glDeleteShader(sh);
      GLint ok = 0;
      glGetProgramiv(prog, GL_LINK_STATUS, &ok);
      if (!ok) {
        char log[2048] = {};
        glGetProgramInfoLog(prog, sizeof log, nullptr, log);
        glDeleteProgram(prog);
        throw isotile::Error(std::string("the check's shader does not link: ") + log);
      }
      const isotile::gl::Buffer operands(in.size() * 8, in.data()), results(out.size() * 8);
      operands.bind(GL_SHADER_STORAGE_BUFFER, 0);
      results.bind(GL_SHADER_STORAGE_BUFFER, 1);
      glProgramUniform1ui(prog, glGetUniformLocation(prog, "u_count"), static_cast<GLuint>(n));
      glUseProgram(prog);
      isotile::gl::dispatch(n);
      results.read(0, out.size() * 8, out.data());
      glUseProgram(0);
      glDeleteProgram(prog);
    }
    isotile::gl::shutdown();
    const char* names[4] = {"a / b", "sqrt(c)", "fma(a, b, d)", "a * b + d (precise)"};
    std::uint64_t differ[4] = {}, worst[4] = {};
    for (std::uint64_t i = 0; i < n; ++i) {
      const double* o = &in[4 * i];
      const double cpu[4] = {o[0] / o[1], std::sqrt(o[2]), std::fma(o[0], o[1], o[3]),
                             o[0] * o[1] + o[3]};
      for (int k = 0; k < 4; ++k) {
        const std::uint64_t u = static_cast<std::uint64_t>(ulps(out[4 * i + k], cpu[k]));
        differ[k] += u != 0;
        if (u > worst[k]) worst[k] = u;
      }
    }
    std::printf("gl_double_check: %s, %llu operand sets\n", renderer.c_str(),
                static_cast<unsigned long long>(n));
    bool all = true;
    for (int k = 0; k < 4; ++k) {
      std::printf("  %-22s %10llu differ from the CPU, worst %llu ulp\n", names[k],
                  static_cast<unsigned long long>(differ[k]),
                  static_cast<unsigned long long>(worst[k]));
      // fma is reported only: the shaders call no fma(), and llvmpipe's is not fused.
      if (k != 2) all = all && differ[k] == 0;
    }
    std::printf("gl_double_check: %s\n",
                all ? "every result equals the CPU's" : "results differ from the CPU's");
    return all ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gl_double_check: %s\n", e.what());
    return 2;
  }
}
