#include "render_command.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/mesh/atomic_file.h"
#include "core/mesh/mesh_io.h"
#include "tiler/cli/cli_common.h"
#ifdef ISOTILE_HAVE_GL
#include "shaders/mesh_render.h"
#endif

namespace isotile {

namespace {

// "WxH" with both whole numbers in [1, 65535].
void parse_size(const std::string& s, int& w, int& h) {
  const std::size_t x = s.find('x');
  bool ok = x != std::string::npos && x > 0 && x + 1 < s.size();
  long a = 0, b = 0;
  if (ok) {
    char *ea = nullptr, *eb = nullptr;
    const std::string sa = s.substr(0, x), sb = s.substr(x + 1);
    a = std::strtol(sa.c_str(), &ea, 10);
    b = std::strtol(sb.c_str(), &eb, 10);
    ok = *ea == '\0' && *eb == '\0' && sa.find_first_not_of("0123456789") == std::string::npos &&
         sb.find_first_not_of("0123456789") == std::string::npos && a >= 1 && b >= 1 &&
         a <= 65535 && b <= 65535;
  }
  if (!ok)
    throw InputError("--size must be WIDTHxHEIGHT in pixels, each at least 1, got '" + s + "'");
  w = static_cast<int>(a);
  h = static_cast<int>(b);
}

void say(bool quiet, const std::string& m) {
  if (!quiet) std::fprintf(stderr, "isotile: %s\n", m.c_str());
}

std::string seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f s", s);
  return buf;
}

#ifdef ISOTILE_HAVE_GL
gl::RenderOptions render_options(const RenderArgs& a) {
  gl::RenderOptions o;
  parse_size(a.size, o.width, o.height);
  gl::parse_view(a.view, o);
  o.colour = a.colour == "normal"  ? gl::RenderColour::Normal
             : a.colour == "solid" ? gl::RenderColour::Solid
                                   : gl::RenderColour::Quality;
  o.wireframe = a.wireframe;
  o.zoom = a.zoom;
  if (!a.center.empty()) {
    std::array<double, 3> c{};
    const char* p = a.center.c_str();
    bool ok = true;
    for (int k = 0; k < 3 && ok; ++k) {
      char* end = nullptr;
      c[k] = std::strtod(p, &end);
      ok = end != p && std::isfinite(c[k]) && (k < 2 ? *end == ',' : *end == '\0');
      p = end + (k < 2 ? 1 : 0);
    }
    if (!ok)
      throw InputError("--center must be X,Y,Z (three finite numbers), got '" + a.center + "'");
    o.center = c;
  }
  if (!(o.zoom > 0) || !std::isfinite(o.zoom)) throw InputError("--zoom must be a positive number");
  return o;
}

// Draws with `render` (render_mesh or render_mesh_file) and writes the picture.
template <class Render>
double draw(Render render, const gl::RenderOptions& o, const std::string& picture, bool quiet) {
  const auto t0 = std::chrono::steady_clock::now();
  gl::RenderStats stats;
  const gl::Picture pic = render(o, &stats);
  gl::write_png(pic, picture);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  say(quiet, "rendered " + std::to_string(stats.triangles) + " triangles in " +
                 std::to_string(stats.pieces) + (stats.pieces == 1 ? " piece" : " pieces") +
                 " to " + picture + " (" + std::to_string(o.width) + "x" +
                 std::to_string(o.height) + ") in " + seconds(s));
  return s;
}
#endif

}  // namespace

void check_picture_path(const std::string& path) {
  if (!ends_with_ci(path, ".png"))
    throw InputError("the picture must be a .png file, got '" + path + "'");
}

CLI::App* add_render_command(CLI::App& app, RenderArgs& a) {
  auto* cmd = app.add_subcommand(
      "render", "Draw a mesh to a PNG picture offscreen with OpenGL (no display needed)");
  cmd->add_option("MESH", a.input, "Mesh file (.ply, .obj, .stl, .off)")->required();
  cmd->add_option("-o,--output", a.output, "Picture (.png)")->required();
  cmd->add_option("--size", a.size, "Picture size WIDTHxHEIGHT in pixels (default 800x600)");
  cmd->add_option("--view", a.view,
                  "iso (default), front, back, left, right, side, top, bottom, or "
                  "AZIMUTH,ELEVATION in degrees (azimuth about +z from the front, -y)");
  cmd->add_option("--colour,--color", a.colour,
                  "quality (radius ratio on the ramp of docs/cli.md, with a colour bar; "
                  "default), normal, or solid")
      ->check(CLI::IsMember({"quality", "normal", "solid"}));
  cmd->add_flag("--wireframe", a.wireframe, "Draw the triangles' edges");
  cmd->add_option("--zoom", a.zoom, "Magnify about the centre (default 1: the mesh fits)");
  cmd->add_option("--center,--centre", a.center,
                  "X,Y,Z: the point in the middle of the picture (default: the middle of the mesh "
                  "as seen from the view)");
  return cmd;
}

int run_render(const RenderArgs& a, bool quiet) {
#ifdef ISOTILE_HAVE_GL
  check_picture_path(a.output);
  cli::check_distinct_files({{"the input", a.input}, {"the output", a.output}}, 1);
  const gl::RenderOptions o = render_options(a);
  say(quiet, "drawing " + a.input);
  draw([&](const gl::RenderOptions& ro,
           gl::RenderStats* st) { return gl::render_mesh_file(a.input, ro, st); },
       o, a.output, quiet);
  return 0;
#else
  (void)a;
  (void)quiet;
  throw InputError("this isotile was built without OpenGL (ISOTILE_GL=OFF): render needs it");
#endif
}

double render_extracted(const Mesh& mesh, const std::string& picture, bool quiet) {
#ifdef ISOTILE_HAVE_GL
  return draw([&](const gl::RenderOptions& ro,
                  gl::RenderStats* st) { return gl::render_mesh(mesh, ro, st); },
              render_options(RenderArgs{}), picture, quiet);
#else
  (void)mesh;
  (void)picture;
  (void)quiet;
  throw InputError("this isotile was built without OpenGL (ISOTILE_GL=OFF): --render needs it");
#endif
}

double render_extracted_file(const std::string& mesh_file, const std::string& picture, bool quiet) {
#ifdef ISOTILE_HAVE_GL
  return draw(
      [&](const gl::RenderOptions& ro, gl::RenderStats* st) {
        // The run's mesh under its temporary name, where the CLI holds its renames.
        return gl::render_mesh_file(HeldCommits::readable(mesh_file).string(), ro, st);
      },
      render_options(RenderArgs{}), picture, quiet);
#else
  (void)mesh_file;
  (void)picture;
  (void)quiet;
  throw InputError("this isotile was built without OpenGL (ISOTILE_GL=OFF): --render needs it");
#endif
}

}  // namespace isotile
