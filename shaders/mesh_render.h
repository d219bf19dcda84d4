// Draws a mesh into a picture offscreen with the process's headless GL context (gl_context.h):
// no window system, on a GPU through EGL's device platform or on llvmpipe. Orthographic, lit by
// a headlight, framed to fit the mesh's bounding box unless told otherwise, coloured by triangle
// quality (radius ratio, on the ramp of colour_ramp.h, with a colour bar), by normal, or in one
// colour; optionally with the triangles' edges drawn. The triangles go to the device in pieces
// of at most `piece_triangles`, so meshes larger than one device buffer are drawn too; the
// picture does not depend on the piece size. The same mesh and options give the same picture on
// the same renderer (tests/test_render.cpp).
//
// Programs: render_mesh.vert and render_mesh.frag (vertex and fragment, built by program() and
// listed in gl_variants.cpp). The colour and depth renderbuffers and the framebuffer are made
// and deleted in each call, so nothing of a render outlives it.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "core/mesh/mesh.h"
#include "picture.h"

namespace isotile::gl {

enum class RenderColour { Quality, Normal, Solid };

struct RenderOptions {
  int width = 800, height = 600;
  // The camera looks at the centre from this direction (degrees): azimuth about +z from -y
  // (0: front, from -y; 90: from +x), elevation above the x-y plane (90: from +z, top).
  double azimuth = 45, elevation = 35.264389682754654;
  RenderColour colour = RenderColour::Quality;
  bool wireframe = false;
  double zoom = 1;                              // > 1 magnifies about the centre
  std::optional<std::array<double, 3>> center;  // default: the bounding box's centre
  // Triangles per piece sent to the device; 0: as many as fit kRenderPieceBytes.
  std::uint64_t piece_triangles = 0;
};

// The largest vertex buffer one piece uses (96 bytes per triangle).
inline constexpr std::uint64_t kRenderPieceBytes = 64ull << 20;

// The fraction of the picture's smaller side left empty around the framed bounding box, on each
// side.
inline constexpr double kRenderMargin = 0.05;

struct RenderStats {
  std::uint64_t triangles = 0;  // drawn (quads as two)
  std::uint64_t pieces = 0;
  // Radius ratios of the drawn triangles (0 when there are none); the mean summed in drawing
  // order. For a triangle mesh these are `isotile quality`'s min and max, and its mean but for
  // the summation order; quads count as the two triangles drawn.
  double quality_min = 0, quality_mean = 0, quality_max = 0;
  double seconds = 0;  // drawing and read-back
};

// The defines of the render program for these options (gl_variants.cpp lists every combination).
std::string render_defines(RenderColour colour, bool wireframe);

// A named view (iso, front, back, left, right, side (= right), top, bottom) or
// "AZIMUTH,ELEVATION" in degrees; InputError otherwise.
void parse_view(const std::string& view, RenderOptions& o);

// Throws InputError for a size below 1 or above the device's limits, a zoom that is not a
// positive number, a non-finite centre or vertex, a picture too small for its colour bar;
// throws like device() when there is no context.
Picture render_mesh(const Mesh& mesh, const RenderOptions& o, RenderStats* stats = nullptr);

// The mesh in a file (PLY, OBJ, STL, OFF). A binary little-endian PLY of the usual layout
// (core/mesh/ply_face_stream.h: isotile's own, the tiler's streamed output) is drawn with only
// its vertices in memory and its faces read piece by piece; any other file is read whole
// (read_mesh). The same picture as render_mesh() of the file's mesh when its faces are all
// triangles (a file mixing triangles and quads is drawn in file order, the mesh triangles
// first). Throws as read_mesh() does for a file it cannot read.
Picture render_mesh_file(const std::filesystem::path& path, const RenderOptions& o,
                         RenderStats* stats = nullptr);

}  // namespace isotile::gl
