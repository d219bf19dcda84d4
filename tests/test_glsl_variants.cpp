// Every GLSL program the GL extractors can build, checked without a GPU: each variant of
// program_variants() (shaders/gl_variants.h) is assembled exactly as program() assembles it and
// compiled and linked by glslang (Debian's glslang-tools), and its AST is searched for the class
// of code that Mesa accepts and NVIDIA's compiler cannot link: a write into a double vector or
// a double matrix through a non-constant index (assignments, compound assignments, ++/--, out
// and inout arguments). The second test shows that the search finds each such write.
#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <unistd.h>
#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "shaders/gl_variants.h"
#include "skip_support.h"

namespace isotile {
namespace {

namespace fs = std::filesystem;

struct Node {
  int depth = 0;
  std::string line;  // source line number as glslang prints it
  std::string text;
};

// glslang's AST dump (`glslangValidator -i`): "S:L<indent>text", two spaces per level.
std::vector<Node> parse_ast(const std::string& dump) {
  static const std::regex row(R"(^\d+:(\d+|\?)( +)(.*)$)");
  std::vector<Node> nodes;
  std::istringstream in(dump);
  for (std::string l; std::getline(in, l);) {
    std::smatch m;
    if (std::regex_match(l, m, row))
      nodes.push_back({static_cast<int>(m[2].length()), m[1].str(), m[3].str()});
  }
  return nodes;
}

// The i-th child of node n (-1 when it has fewer children).
int child(const std::vector<Node>& nodes, int n, int i) {
  for (int k = n + 1, seen = 0; k < static_cast<int>(nodes.size()); ++k) {
    if (nodes[k].depth <= nodes[n].depth) break;
    if (nodes[k].depth == nodes[n].depth + 2 && seen++ == i) return k;
  }
  return -1;
}

// The type in a node's last parenthesised group: "( temp 3-component vector of double)".
std::string node_type(const std::string& text) {
  if (text.empty() || text.back() != ')') return "";
  int depth = 0;
  for (int i = static_cast<int>(text.size()) - 1; i >= 0; --i) {
    if (text[i] == ')') ++depth;
    if (text[i] == '(' && --depth == 0) return text.substr(i + 1, text.size() - i - 2);
  }
  return "";
}

bool double_vector_or_matrix(const std::string& text) {
  const std::string t = node_type(text);
  auto ends = [&](const std::string& s) {
    return t.size() >= s.size() && t.compare(t.size() - s.size(), s.size(), s) == 0;
  };
  return t.find("array of") == std::string::npos &&
         (ends("vector of double") || ends("matrix of double"));
}

// Whether the l-value at node n writes through a non-constant index into a double vector or
// matrix, anywhere along its chain of indexing.
bool writes_double_lane(const std::vector<Node>& nodes, int n) {
  while (n >= 0) {
    const std::string& t = nodes[n].text;
    if (t.starts_with("indirect index")) {
      const int base = child(nodes, n, 0);
      if (base >= 0 && double_vector_or_matrix(nodes[base].text)) return true;
      n = base;
    } else if (t.starts_with("direct index") || t.starts_with("vector swizzle") ||
               t.find(": direct index for structure") != std::string::npos) {
      n = child(nodes, n, 0);
    } else {
      return false;
    }
  }
  return false;
}

// "file line: what" for every such write in a glslang AST dump.
std::vector<std::string> double_lane_writes(const std::string& dump) {
  const std::vector<Node> nodes = parse_ast(dump);
  // Out and inout parameters per function signature ("name(d1;vd3;").
  std::map<std::string, std::vector<bool>> writes_param;
  for (int n = 0; n < static_cast<int>(nodes.size()); ++n) {
    const std::string& t = nodes[n].text;
    if (!t.starts_with("Function Definition: ")) continue;
    const std::string sig = t.substr(21, t.find(" (") - 21);
    const int params = child(nodes, n, 0);
    std::vector<bool> out;
    if (params >= 0 && nodes[params].text.starts_with("Function Parameters:"))
      for (int i = 0, p; (p = child(nodes, params, i)) >= 0; ++i) {
        const std::string type = node_type(nodes[p].text);
        out.push_back(type.starts_with(" out ") || type.starts_with(" inout ") ||
                      type.starts_with("out ") || type.starts_with("inout "));
      }
    writes_param[sig] = out;
  }
  std::vector<std::string> found;
  // With several stages glslang prints each stage's tree, then the linked ones: report once.
  auto report = [&](int n, const std::string& how) {
    const std::string w = "line " + nodes[n].line + ": " + how;
    if (std::find(found.begin(), found.end(), w) == found.end()) found.push_back(w);
  };
  for (int n = 0; n < static_cast<int>(nodes.size()); ++n) {
    const std::string& t = nodes[n].text;
    const bool assign = t.starts_with("move second child to first child") ||
                        t.find("second child into first child") != std::string::npos;
    const bool step = t.starts_with("Pre-Increment") || t.starts_with("Post-Increment") ||
                      t.starts_with("Pre-Decrement") || t.starts_with("Post-Decrement");
    if ((assign || step) && writes_double_lane(nodes, child(nodes, n, 0)))
      report(n, assign ? "assignment into a double lane through a non-constant index"
                       : "++/-- on a double lane through a non-constant index");
    if (t.starts_with("Function Call: ")) {
      const std::string sig = t.substr(15, t.find(" (") - 15);
      const auto it = writes_param.find(sig);
      if (it == writes_param.end()) continue;
      for (std::size_t i = 0; i < it->second.size(); ++i)
        if (it->second[i] && writes_double_lane(nodes, child(nodes, n, static_cast<int>(i))))
          report(n, "out/inout argument " + std::to_string(i) + " of " + sig +
                        " is a double lane through a non-constant index");
    }
  }
  return found;
}

const char* stage_extension(GLenum type) {
  switch (type) {
    case GL_COMPUTE_SHADER:
      return ".comp";
    case GL_VERTEX_SHADER:
      return ".vert";
    case GL_GEOMETRY_SHADER:
      return ".geom";
    case GL_FRAGMENT_SHADER:
      return ".frag";
  }
  return ".glsl";
}

struct Command {
  int status = -1;
  std::string output;
};

Command run(const std::string& command) {
  Command r;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (!p) return r;
  std::array<char, 4096> buf;
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;)
    r.output.append(buf.data(), n);
  r.status = pclose(p);
  return r;
}

class Glslang : public ::testing::Test {
 protected:
  void SetUp() override {
#ifdef ISOTILE_GLSLANG
    validator_ = ISOTILE_GLSLANG;
#endif
    if (validator_.empty() || !fs::exists(validator_))
      ISOTILE_SKIP(Glslang, "glslangValidator not found (Debian package glslang-tools)");
    dir_ = fs::temp_directory_path() /
           ("isotile-glsl-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!dir_.empty()) fs::remove_all(dir_);
  }

  // Compiles and links the stages (name, source) with glslang; the AST dump, or the failure.
  Command validate(const std::string& name,
                   const std::vector<std::pair<std::string, std::string>>& stages) {
    std::string command = validator_ + " -l -i";
    for (const auto& [file, source] : stages) {
      const fs::path path = dir_ / (name + "-" + file);
      std::ofstream(path) << source;
      command += " '" + path.string() + "'";
    }
    return run(command);
  }

  std::string validator_;
  fs::path dir_;
};

TEST_F(Glslang, EveryProgramVariantCompilesLinksAndWritesNoDoubleLaneByIndex) {
  const std::vector<gl::ProgramVariant> variants = gl::program_variants();
  // Every method, path and sample type is in the table (a gross check that it was not emptied).
  ASSERT_GE(variants.size(), 100u);
  std::mutex m;
  std::vector<std::string> failures;
  tbb::parallel_for(std::size_t{0}, variants.size(), [&](std::size_t i) {
    const gl::ProgramVariant& v = variants[i];
    std::vector<std::pair<std::string, std::string>> stages;
    for (const gl::Stage& s : v.stages) {
      std::string file(s.file);
      file = file.substr(0, file.find('.')) + stage_extension(s.type);
      stages.emplace_back(file, gl::stage_source(s, v.defines));
    }
    const Command r = validate("v" + std::to_string(i), stages);
    std::string problem;
    if (r.status != 0) {
      problem = "glslang fails:\n" + r.output.substr(0, 2000);
    } else {
      for (const std::string& w : double_lane_writes(r.output)) problem += "\n  " + w;
    }
    if (!problem.empty()) {
      std::lock_guard lock(m);
      failures.push_back(v.what + " (" + std::string(v.stages.front().file) + "): " + problem);
    }
  });
  for (const std::string& f : failures) ADD_FAILURE() << f;
  std::printf("%zu program variants checked\n", variants.size());
  EXPECT_TRUE(failures.empty()) << failures.size() << " of " << variants.size()
                                << " program variants fail";
}

// The search finds each kind of write that NVIDIA rejects, and none of the forms it accepts.
TEST_F(Glslang, SearchFindsEveryKindOfDoubleLaneWrite) {
  const std::string source = R"(#version 450 core
layout(local_size_x = 1) in;
layout(std430, binding = 0) buffer B { double o[]; };
void set_out(out double x) { x = 1.0LF; }
void set_inout(inout double x) { x += 1.0LF; }
void by_value(double x) { o[1] = x; }
void whole(inout dvec3 v) { v.x = 2.0LF; }
struct S { dvec3 p; };
void main() {
  int a = int(o[0]);
  dvec3 g = dvec3(0.0LF);
  dmat3 m = dmat3(1.0LF);
  S s;
  s.p = dvec3(0.0LF);
  g[a] = 1.0LF;           // line 15: found
  g[a] += 2.0LF;          // line 16: found
  g[a]++;                 // line 17: found
  --g[a];                 // line 18: found
  set_out(g[a]);          // line 19: found
  set_inout(g[a]);        // line 20: found
  m[a][a] = 3.0LF;        // line 21: found
  m[a] = dvec3(1.0LF);    // line 22: found
  s.p[a] = 4.0LF;         // line 23: found
  double arr[3];
  arr[a] = 5.0LF;
  dvec3 darr[2];
  darr[a] = dvec3(1.0LF);
  vec3 f = vec3(0.0);
  f[a] = 1.0;
  ivec3 k = ivec3(0);
  k[a] += 1;
  g[1] = 3.0LF;
  m[1][2] = 3.0LF;
  whole(g);
  by_value(g[a]);
  o[a] = g[a] + m[a][a] + s.p[a] + arr[a] + darr[a].x + f[a] + double(k[a]);
}
)";
  const Command r = validate("search", {{"probe.comp", source}});
  ASSERT_EQ(r.status, 0) << r.output;
  std::vector<std::string> lines;
  for (const std::string& w : double_lane_writes(r.output)) lines.push_back(w.substr(5, 2));
  EXPECT_EQ(lines, (std::vector<std::string>{"15", "16", "17", "18", "19", "20", "21", "22", "23"}))
      << ::testing::PrintToString(double_lane_writes(r.output));
}

}  // namespace
}  // namespace isotile
