#include "gl_variants.h"

#include <map>
#include <string_view>

#include "core/extract/dual_contouring.h"
#include "dc_gl_shared.h"
#include "hp_pyramid.h"
#include "macet_gl.h"
#include "mesh_render.h"
#include "sample_upload.h"

namespace isotile::gl {

namespace {

using Variants = std::map<std::string, ProgramVariant>;

void add(Variants& out, std::string what, std::vector<Stage> stages, const std::string& defines,
         std::vector<std::string> varyings = {}) {
  const std::string key = program_key(stages, defines);
  out.try_emplace(key,
                  ProgramVariant{std::move(what), std::move(stages), defines, std::move(varyings)});
}

std::string with_base(const std::string& defines) {
  std::string s = defines;  // appended, not concatenated: GCC 12's -Wrestrict
  s += "#define BASE\n";
  return s;
}

// The count pyramid's passes (mc_histopyramid.cpp, dc_histopyramid.cpp) over `defines`.
void add_pyramid(Variants& out, const std::string& what, const std::string& defines) {
  // One level per pass (a software device's) and several (hp_pyramid.h).
  for (const int per_pass : {1, kMaxLevelsPerPass}) {
    const std::string levels = per_pass == 1 ? ", one level per pass" : "";
    add(out, what + " reduce (base)" + levels, {{GL_COMPUTE_SHADER, "hp_reduce.comp"}},
        pyramid_pass_defines(defines, per_pass, true));
    add(out, what + " reduce" + levels, {{GL_COMPUTE_SHADER, "hp_reduce.comp"}},
        pyramid_pass_defines(defines, per_pass));
    add(out, what + " down-sweep" + levels, {{GL_COMPUTE_SHADER, "hp_downsweep.comp"}},
        pyramid_pass_defines(defines, per_pass));
    add(out, what + " down-sweep, face offsets" + levels,
        {{GL_COMPUTE_SHADER, "hp_downsweep.comp"}},
        pyramid_pass_defines(defines, per_pass, false, true));
  }
  add(out, what + " prefix", {{GL_COMPUTE_SHADER, "hp_prefix.comp"}}, defines);
}

// An output pass of the HistoPyramid in both designs (hp_pyramid.h's HpOutput).
void add_output_pass(Variants& out, const std::string& what, std::string_view file,
                     const std::string& defines) {
  for (const HpOutput o : {HpOutput::Descend, HpOutput::Scatter})
    add(out, what + (o == HpOutput::Scatter ? ", per element" : ""), {{GL_COMPUTE_SHADER, file}},
        output_pass_defines(defines, o));
}

// Marching Cubes and Macet: histopyramid_mesh() and geometry_shader_mesh() (gl_program.h) with
// the defines "samples + NORMALS + the method's", and Macet's prepare passes (macet_gl.cpp).
void add_edge_methods(Variants& out) {
  for (const bool macet : {false, true})
    for (const ScalarType type : kSampleTypes)
      for (const bool normals : {false, true}) {
        std::string defines = sample_defines(type);
        if (normals) defines += "#define NORMALS\n";
        if (macet) defines += macet_defines();
        const std::string what = std::string(macet ? "macet" : "mc") + ", " +
                                 std::string(scalar_name(type)) + " samples" +
                                 (normals ? ", normals:" : ":");
        add(out, what + " hp classify", {{GL_COMPUTE_SHADER, "hp_classify.comp"}}, defines);
        add_pyramid(out, what + " hp", defines);
        add_output_pass(out, what + " hp vertices", "hp_vertices.comp", defines);
        add_output_pass(out, what + " hp triangles", "hp_triangles.comp", defines);
        std::vector<std::string> varyings = {"tf_key", "tf_cell", "tf_pos"};
        if (normals) varyings.push_back("tf_nrm");
        add(out, what + " gs",
            {{GL_VERTEX_SHADER, "gs_mc.vert"}, {GL_GEOMETRY_SHADER, "gs_mc.geom"}}, defines,
            varyings);
        if (macet) {
          add(out, what + " push", {{GL_COMPUTE_SHADER, "macet_push.comp"}}, defines);
          add(out, what + " linear", {{GL_COMPUTE_SHADER, "macet_linear.comp"}}, defines);
          add(out, what + " smooth", {{GL_COMPUTE_SHADER, "macet_smooth.comp"}}, defines);
        }
      }
}

// Dual Contouring (dc_histopyramid.cpp, dc_geometry_shader.cpp): every option dc_defines() reads.
void add_dual_contouring(Variants& out) {
  for (const ScalarType type : kSampleTypes)
    for (const DcVertices vertices : {DcVertices::Cell, DcVertices::Patch})
      for (const DcSolver solver : {DcSolver::MassPoint, DcSolver::Particle, DcSolver::Qef})
        for (const DcHermite hermite : {DcHermite::Central, DcHermite::Eno})
          for (const bool normals : {false, true})
            for (const bool quads : {false, true}) {
              DualContouringOptions o;
              o.vertices = vertices;
              o.solver = solver;
              o.hermite = hermite;
              o.normals = normals;
              o.keep_quads = quads;
              const std::string samples = sample_defines(type);
              const std::string what = "dc, " + std::string(scalar_name(type)) + " samples:";
              add_pyramid(out, what + " hp", samples + dc_defines(o, DcPass::Pyramid));
              add(out, what + " classify", {{GL_COMPUTE_SHADER, "dc_hp_classify.comp"}},
                  samples + dc_defines(o, DcPass::Classify));
              add_output_pass(out, what + " vertices", "dc_hp_vertices.comp",
                              samples + dc_defines(o, DcPass::Vertices));
              const std::string faces = samples + dc_defines(o, DcPass::Faces);
              add_output_pass(out, what + " hp quads", "dc_hp_quads.comp", faces);
              add(out, what + " gs faces",
                  {{GL_VERTEX_SHADER, "dc_gs.vert"}, {GL_GEOMETRY_SHADER, "dc_gs.geom"}}, faces,
                  {"tf_vertex", "tf_elem"});
            }
}

// The count pyramid's other layouts, built by tests/benchmarks/bench_hp_layouts.cpp only.
void add_benchmark_layouts(Variants& out) {
  // Stage names view these literals (Stage::file is a string_view).
  static constexpr const char* kPasses[] = {
      "hp_bench_linear_find.comp", "hp_bench_block_classify.comp",
      "hp_bench_block_find.comp",  "hp_bench_tex_classify.comp",
      "hp_bench_tex_find.comp",    "hp_bench_compact_scatter.comp"};
  static constexpr const char* kReduces[] = {"hp_bench_block_reduce.comp",
                                             "hp_bench_tex_reduce.comp"};
  for (const ScalarType type : kSampleTypes) {
    const std::string d = sample_defines(type);
    const std::string what = "bench, " + std::string(scalar_name(type)) + " samples: ";
    for (const char* file : kPasses) add(out, what + file, {{GL_COMPUTE_SHADER, file}}, d);
    for (const char* file : kReduces) {
      add(out, what + file, {{GL_COMPUTE_SHADER, file}}, d);
      add(out, what + file + " (base)", {{GL_COMPUTE_SHADER, file}}, with_base(d));
    }
  }
}

// `isotile render`'s vertex and fragment program (mesh_render.cpp), per colouring and wireframe.
void add_render(Variants& out) {
  for (const RenderColour colour :
       {RenderColour::Quality, RenderColour::Normal, RenderColour::Solid})
    for (const bool wireframe : {false, true})
      add(out,
          std::string("render: ") +
              (colour == RenderColour::Quality  ? "quality"
               : colour == RenderColour::Normal ? "normal"
                                                : "solid") +
              (wireframe ? ", wireframe" : ""),
          render_stages(), render_defines(colour, wireframe));
}

}  // namespace

std::vector<ProgramVariant> program_variants() {
  Variants v;
  add_edge_methods(v);
  add_dual_contouring(v);
  add_benchmark_layouts(v);
  add_render(v);
  std::vector<ProgramVariant> out;
  out.reserve(v.size());
  for (auto& [key, variant] : v) out.push_back(std::move(variant));
  return out;
}

}  // namespace isotile::gl
