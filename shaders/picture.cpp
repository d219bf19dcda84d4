#include "picture.h"

#include <png.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <csetjmp>
#include <cstdio>

#include "colour_ramp.h"
#include "core/errors.h"
#include "core/mesh/atomic_file.h"

namespace isotile::gl {

namespace {

// 5x7 glyphs, one row a byte, bit 4 the leftmost pixel: what the colour bar writes.
struct Glyph {
  char c;
  std::array<std::uint8_t, 7> rows;
};
constexpr Glyph kFont[] = {
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}},
    {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}},
    {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}},
    {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}},
    {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}},
    {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}},
    {'-', {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00}},
    {' ', {0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},
    {'a', {0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F}},
    {'e', {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E}},
    {'g', {0x00, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E}},
    {'i', {0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E}},
    {'l', {0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'m', {0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11}},
    {'n', {0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11}},
    {'o', {0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E}},
    {'r', {0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10}},
    {'s', {0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E}},
    {'t', {0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06}},
    {'x', {0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11}},
};

const Glyph& glyph(char c) {
  for (const Glyph& g : kFont)
    if (g.c == c) return g;
  throw Error(std::string("the picture font has no character '") + c + "'");
}

void fill(Picture& p, int x0, int y0, int x1, int y1, const Rgb8& c) {
  x0 = std::max(x0, 0), y0 = std::max(y0, 0);
  x1 = std::min(x1, p.width), y1 = std::min(y1, p.height);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x)
      std::copy(c.begin(), c.end(), p.rgb.begin() + (std::size_t(y) * p.width + x) * 3);
}

std::string fixed3(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", v);
  return buf;
}

// The font and bar grow with the picture: 1 up to 599 pixels wide, 2 from 600x480, ...
int bar_scale(int width, int height) {
  return std::max(1, std::min(width / 300, height / 240));
}

}  // namespace

int text_width(const std::string& text, int scale) {
  return static_cast<int>(text.size()) * 6 * scale;
}

void draw_text(Picture& p, int x, int y, int scale, const std::string& text) {
  for (char c : text) {
    const Glyph& g = glyph(c);
    for (int r = 0; r < 7; ++r)
      for (int b = 0; b < 5; ++b)
        if (g.rows[r] & (0x10 >> b))
          fill(p, x + b * scale, y + r * scale, x + (b + 1) * scale, y + (r + 1) * scale,
               {0, 0, 0});
    x += 6 * scale;
  }
}

int colour_bar_height(int width, int height) {
  return 26 * bar_scale(width, height);
}

BarExtent colour_bar_extent(int width, int height) {
  const int s = bar_scale(width, height);
  const int top = height - colour_bar_height(width, height);
  return {8 * s, width - 8 * s, top + 4 * s, top + 12 * s};
}

void draw_colour_bar(Picture& p, double min, double mean, double max, std::uint64_t triangles) {
  const int s = bar_scale(p.width, p.height);
  const int top = p.height - colour_bar_height(p.width, p.height);
  fill(p, 0, top, p.width, p.height, {255, 255, 255});
  const BarExtent e = colour_bar_extent(p.width, p.height);
  const int span = std::max(1, e.right - e.left);
  for (int x = e.left; x < e.right; ++x) {
    // The pixel's centre on [0, 1].
    const std::array<double, 3> c = quality_colour((x - e.left + 0.5) / span);
    const Rgb8 rgb = {static_cast<std::uint8_t>(std::lround(c[0] * 255)),
                      static_cast<std::uint8_t>(std::lround(c[1] * 255)),
                      static_cast<std::uint8_t>(std::lround(c[2] * 255))};
    fill(p, x, e.top, x + 1, e.bottom, rgb);
  }
  if (triangles == 0) {
    draw_text(p, e.left, e.bottom + 4 * s, s, "no triangles");
    return;
  }
  // Ticks from just above the bar to just below it, at the values' pixels.
  for (double v : {min, mean, max}) {
    const int x = e.left + std::clamp(static_cast<int>(std::floor(v * span)), 0, span - 1);
    fill(p, x - (s - 1) / 2, e.top - 2 * s, x - (s - 1) / 2 + s, e.bottom + 2 * s, {0, 0, 0});
  }
  draw_text(p, e.left, e.bottom + 4 * s, s,
            "min " + fixed3(min) + "  mean " + fixed3(mean) + "  max " + fixed3(max));
}

namespace {

[[noreturn]] void png_fail(png_structp png, png_const_charp message) {
  auto* why = static_cast<std::string*>(png_get_error_ptr(png));
  *why = message;
  png_longjmp(png, 1);
}

void png_warn(png_structp, png_const_charp) {}

// libpng reports errors by longjmp: nothing with a destructor lives in this frame.
bool write_png_stream(const Picture& p, std::FILE* f, std::string* why) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, why, png_fail, png_warn);
  if (!png) return *why = "libpng could not start", false;
  png_infop info = png_create_info_struct(png);
  if (!info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    if (why->empty()) *why = "libpng could not start";
    return false;
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, static_cast<png_uint_32>(p.width), static_cast<png_uint_32>(p.height), 8,
               PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < p.height; ++y)
    png_write_row(png, p.rgb.data() + std::size_t(y) * p.width * 3);
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

void write_png(const Picture& p, const std::filesystem::path& path) {
  if (p.width <= 0 || p.height <= 0 || p.rgb.size() != std::size_t(p.width) * p.height * 3)
    throw Error("write_png: the picture's pixels do not match its size");
  AtomicFile file(path);
  std::string why;
  if (!write_png_stream(p, file.stream(), &why))
    throw IoError("cannot write " + path.string() + ": " + why);
  if (std::ferror(file.stream())) throw IoError("cannot write " + path.string());
  file.commit();
}

}  // namespace isotile::gl
