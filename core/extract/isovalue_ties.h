// Samples equal to the isovalue ("ties"), as Macet and Dual Contouring treat them. Internal to
// core/.
//
// A tie is inside (value >= iso), and the crossing on every crossed edge from it falls exactly on
// it. With one crossed edge that is right (a surface through a plane of samples stays on it), but
// integer isovalues on integer CT data make ties common, and many have more: bonsai at iso 50 has
// 15,989 ties, 10,340 of them pinned (both neighbours along some axis outside: one-sample-thin
// sheets, rods and specks at exactly the isovalue). There Marching Cubes gives 79,746 degenerate
// (zero-area) triangles, DC 26,781 and Macet 4,674.
//
// Where crossings would coincide, Macet and DC put a tie's crossing kTieOffset edge lengths from
// it along its edge, toward the outside sample, so the surface moves by at most kTieOffset voxels,
// and only there:
//   Macet: a grid vertex still at the isovalue after its displacement, with two or more crossed
//          edges (the crossings on them would be one point; a tie with a free side is usually
//          pushed off the isovalue first and keeps its crossings on the interpolant). "Still at
//          the isovalue": exactly, or a tie moved along the level set to within the root
//          search's tolerance of it (label maps: the interpolant there is the isovalue up to
//          rounding, or nearly). In float32 data a tie is a sample holding the float nearest
//          the isovalue (--iso 0.1 on samples of 0.1f, 1.5e-9 above it).
//   DC:    a pinned tie. Two cells' vertices coincide only where every crossing of both cells
//          lies on one tie they share, which needs a pinned tie; other ties keep their exact
//          crossings, so surfaces and sharp edges through sample planes stay exact.
// Marching Cubes keeps the textbook crossings (it is the reference the GL backends match).
// docs/quality.md has the measurements behind the value.
#pragma once

namespace isotile::detail {

inline constexpr double kTieOffset = 0.2;

}  // namespace isotile::detail
