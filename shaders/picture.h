// A picture in memory (8-bit RGB, top row first), the colour bar of a quality picture and its
// labels in a small built-in bitmap font, and the PNG writer (libpng, written atomically like
// every output: core/mesh/atomic_file.h). No GL here: mesh_render.cpp draws into a Picture.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace isotile::gl {

struct Picture {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // width * height * 3, top row first
};

// Draws `text` with its top-left corner at (x, y), each font pixel a `scale` x `scale` square of
// black; clipped to the picture. The font has the digits, '.', '-', ' ' and the lower-case
// letters a, e, g, i, l, m, n, o, r, s, t, x; other characters throw Error.
void draw_text(Picture& p, int x, int y, int scale, const std::string& text);
// Width in pixels of `text` drawn at `scale` (6 pixels per character at scale 1).
int text_width(const std::string& text, int scale);

// The height of the colour bar band at the bottom of a quality picture of this size.
int colour_bar_height(int width, int height);

// Draws the colour bar band over the picture's bottom colour_bar_height() rows: the quality ramp
// (colour_ramp.h) over [0, 1] left to right, tick marks at min, mean and max, and under it
// "min M  mean A  max X" (three decimals), or "no triangles" when `triangles` is 0.
void draw_colour_bar(Picture& p, double min, double mean, double max, std::uint64_t triangles);

// The ramp's x range in the band: the bar spans [left, right) (for tests).
struct BarExtent {
  int left = 0, right = 0, top = 0, bottom = 0;
};
BarExtent colour_bar_extent(int width, int height);

// Writes the picture as an 8-bit RGB PNG, atomically (the target appears only when complete).
// Throws IoError when it cannot be written.
void write_png(const Picture& p, const std::filesystem::path& path);

}  // namespace isotile::gl
