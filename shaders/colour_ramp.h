// The colour ramp of triangle quality (radius ratio, core/mesh/mesh_quality.h) in pictures drawn
// by `isotile render`: defined once here, used by the fragment shader (uploaded as a uniform
// array) and by the picture's colour bar, so the bar reads the mesh's colours exactly.
//
// Entry i is the colour of q = i / (kQualityRampSize - 1); between entries the colour is
// interpolated linearly. Bad triangles are red, fair ones orange to yellow, good ones green and
// the best (near equilateral) blue:
//
//   q     0.0          0.2          0.4           0.6           0.8            1.0
//   rgb   120, 0, 20   215, 40, 30  245, 130, 40  250, 220, 90  140, 210, 120  50, 130, 200
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

namespace isotile::gl {

using Rgb8 = std::array<std::uint8_t, 3>;

inline constexpr int kQualityRampSize = 6;
inline constexpr std::array<Rgb8, kQualityRampSize> kQualityRamp = {{
    {120, 0, 20},
    {215, 40, 30},
    {245, 130, 40},
    {250, 220, 90},
    {140, 210, 120},
    {50, 130, 200},
}};

// The ramp's colour of quality q (clamped to [0, 1]) in [0, 1] per channel, as the shader
// computes it (render_mesh.frag's ramp()).
inline std::array<double, 3> quality_colour(double q) {
  const double t = std::clamp(std::isfinite(q) ? q : 0.0, 0.0, 1.0) * (kQualityRampSize - 1);
  const int i = std::min(static_cast<int>(t), kQualityRampSize - 2);
  const double f = t - i;
  std::array<double, 3> c{};
  for (int k = 0; k < 3; ++k)
    c[k] = (kQualityRamp[i][k] * (1 - f) + kQualityRamp[i + 1][k] * f) / 255.0;
  return c;
}

}  // namespace isotile::gl
