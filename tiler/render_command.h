// `isotile render MESH -o PICTURE.png` and `extract --render PICTURE.png`: the command line's side
// of shaders/mesh_render.h (options, reading the mesh, writing the PNG). Without OpenGL in the
// build every entry point throws InputError saying so.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "core/mesh/mesh.h"

namespace isotile {

struct RenderArgs {
  std::string input, output;
  std::string size = "800x600", view = "iso", colour = "quality", center;
  bool wireframe = false;
  double zoom = 1;
};

// Adds the `render` subcommand and its options.
CLI::App* add_render_command(CLI::App& app, RenderArgs& args);

// Reads the mesh, draws it and writes the picture; progress on stderr unless `quiet`.
int run_render(const RenderArgs& args, bool quiet);

// Throws InputError unless `path` names a .png file (checked before an extraction starts).
void check_picture_path(const std::string& path);

// `extract --render`: draws `mesh` (framed, iso view, coloured by quality, 800x600) into
// `picture`; returns the seconds it took.
double render_extracted(const Mesh& mesh, const std::string& picture, bool quiet);
// The same for a mesh written to `mesh_file` (the out-of-core path): a binary PLY's faces are
// read in pieces (shaders/mesh_render.h, render_mesh_file()).
double render_extracted_file(const std::string& mesh_file, const std::string& picture, bool quiet);

}  // namespace isotile
