// Does the GL device round double division as the CPU does, keep `precise` a * b + c unfused,
// and does the shaders' square root (sqrt_rn(), shaders/glsl/sqrt_rn.glsl) give the CPU's
// std::sqrt bit for bit? GLSL asks only for float precision of double `/` and `sqrt` (GLSL 4.50,
// 4.7.1), and Macet's guards and DC's solvers decide on such values, so the GL meshes equal the
// CPU's bit for bit only where these agree (docs/gl.md). This runs one compute pass over random
// operands, computes the same on the CPU, and prints how many results differ and by how many
// units in the last place; exit status 1 when any checked one differs. sqrt_rn() is checked twice:
// from the device's sqrt() as the shaders call it, and from first guesses up to 6 ulp off the
// root (so that its steps run on a device whose own sqrt() is already right, as llvmpipe's is).
// The device's own sqrt() and fma() are reported only: the shaders call neither directly, and
// llvmpipe's double fma is not fused. On llvmpipe every checked result must agree (a ctest); on a
// GPU it is part of the GPU checks (tests/gpu/run_gpu_checks.sh).
//
//   gl_double_check [COUNT]        (default 1000000 operand sets)
#include <glad/gl.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/errors.h"
#include "shaders/gl_context.h"
#include "shaders/gl_program.h"

namespace {

// Each operand set is two dvec4: (a, b, c, d) and (guess, 0, 0, 0); each result two: (a / b,
// sqrt(c), fma(a, b, d), a * b + d) and (sqrt_rn(c), sqrt_rn_from(c, guess), 0, 0).
const char* kShader = R"(
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer In { dvec4 operands[]; };
layout(std430, binding = 1) writeonly buffer Out { dvec4 results[]; };
uniform uint u_count;
void main() {
  uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 256u;
  if (i >= u_count) return;
  dvec4 o = operands[2u * i];
  double guess = operands[2u * i + 1u].x;
  precise double q = o.x / o.y;
  precise double r = sqrt(o.z);
  precise double f = fma(o.x, o.y, o.w);
  precise double p = o.x * o.y + o.w;
  results[2u * i] = dvec4(q, r, f, p);
  results[2u * i + 1u] = dvec4(sqrt_rn(o.z), sqrt_rn_from(o.z, guess), 0.0LF, 0.0LF);
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
    std::vector<double> in(8 * n), out(8 * n);
    std::mt19937_64 rng(20261126);
    // Operands over many binades, both signs for the quotient and fma; sqrt of positives.
    std::uniform_real_distribution<double> mant(1.0, 2.0);
    std::uniform_int_distribution<int> expo(-40, 40), sign(0, 1), off(-6, 6);
    auto any = [&] { return (sign(rng) ? -1.0 : 1.0) * std::ldexp(mant(rng), expo(rng)); };
    // Roots whose rounding sqrt_rn() must get at its edges: exact squares, the ends of its range
    // [1, 4), the squares of neighbours of 1 and 2, zero, and values from the smallest subnormal
    // to the largest finite.
    const double edges[] = {0.0,
                            1.0,
                            2.0,
                            4.0,
                            std::nextafter(4.0, 0.0),
                            std::nextafter(1.0, 2.0),
                            std::nextafter(2.0, 0.0),
                            std::nextafter(1.0, 2.0) * std::nextafter(1.0, 2.0),
                            std::nextafter(2.0, 0.0) * std::nextafter(2.0, 0.0),
                            9.0,
                            0.25,
                            std::numeric_limits<double>::min(),
                            std::numeric_limits<double>::max(),
                            1e-300,
                            1e300,
                            std::numeric_limits<double>::denorm_min(),
                            1e-310,
                            0x1.fffffffffffffp-1023};
    for (std::uint64_t i = 0; i < n; ++i) {
      double* o = &in[8 * i];
      o[0] = any();
      o[1] = any();
      if (i < std::size(edges)) {
        o[2] = edges[i];
      } else if (i % 4 == 0) {  // an exact square: a root of 26 significant bits
        const double m = std::floor(std::ldexp(mant(rng), 25));
        const double root = std::ldexp(m, expo(rng) - 25);
        o[2] = root * root;
      } else {
        o[2] = std::ldexp(mant(rng), expo(rng));
      }
      o[3] = any();
      // A first guess for sqrt_rn_from(): the root moved by up to 6 ulp either way.
      double guess = std::sqrt(o[2]);
      for (int k = off(rng); k != 0; k += k > 0 ? -1 : 1)
        guess = std::nextafter(guess, k > 0 ? HUGE_VAL : 0.0);
      o[4] = guess;
    }
    std::string renderer;
    {
      isotile::gl::Scope scope;
      renderer = isotile::gl::device().renderer;
      const GLuint sh = glCreateShader(GL_COMPUTE_SHADER);
      // The shaders' sqrt_rn() as gl_program.cpp prepends it.
      const std::string source = std::string("#version 450 core\n") +
                                 std::string(isotile::gl::embedded_glsl("sqrt_rn.glsl")) + kShader;
      const char* text = source.c_str();
      glShaderSource(sh, 1, &text, nullptr);
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
    // Checked rows decide the exit status; the device's own sqrt() and fma() are reported only.
    struct Row {
      const char* name;
      bool checked;
    };
    const Row rows[6] = {{"a / b", true},         {"sqrt(c), the device's", false},
                         {"fma(a, b, d)", false}, {"a * b + d (precise)", true},
                         {"sqrt_rn(c)", true},    {"sqrt_rn from +-6 ulp", true}};
    std::uint64_t differ[6] = {}, worst[6] = {};
    std::printf("gl_double_check: %s, %llu operand sets\n", renderer.c_str(),
                static_cast<unsigned long long>(n));
    for (std::uint64_t i = 0; i < n; ++i) {
      const double* o = &in[8 * i];
      const double root = std::sqrt(o[2]);
      const double cpu[6] = {o[0] / o[1],        root, std::fma(o[0], o[1], o[3]),
                             o[0] * o[1] + o[3], root, root};
      const double gpu[6] = {out[8 * i],     out[8 * i + 1], out[8 * i + 2],
                             out[8 * i + 3], out[8 * i + 4], out[8 * i + 5]};
      for (int k = 0; k < 6; ++k) {
        const std::uint64_t u = static_cast<std::uint64_t>(ulps(gpu[k], cpu[k]));
        // The first few differences of a checked row, operands exactly (%a), to reproduce them.
        if (u != 0 && rows[k].checked && differ[k] < 4)
          std::printf("  %s differs: a %a b %a c %a d %a guess %a: device %a, CPU %a\n",
                      rows[k].name, o[0], o[1], o[2], o[3], o[4], gpu[k], cpu[k]);
        differ[k] += u != 0;
        if (u > worst[k]) worst[k] = u;
      }
    }
    bool all = true;
    for (int k = 0; k < 6; ++k) {
      std::printf("  %-24s %10llu differ from the CPU, worst %llu ulp%s\n", rows[k].name,
                  static_cast<unsigned long long>(differ[k]),
                  static_cast<unsigned long long>(worst[k]), rows[k].checked ? "" : " (reported)");
      if (rows[k].checked) all = all && differ[k] == 0;
    }
    std::printf("gl_double_check: %s\n",
                all ? "every result equals the CPU's" : "results differ from the CPU's");
    return all ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gl_double_check: %s\n", e.what());
    return 2;
  }
}
