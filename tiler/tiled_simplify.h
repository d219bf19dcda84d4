// Out-of-core extraction with simplification (`isotile extract --memory SIZE --simplify R`): no
// more than one brick's extraction and simplification, or one seam cell's, is in memory at once.
//
//   1. Count each brick's vertices and faces (classification only), to cut bricks whose
//      extraction and simplification would not fit the budget into thinner z-slices.
//   2. Extract each brick (or slice), simplify it with its seam vertices locked
//      (core/simplify/simplify.h: simplify_piece), and spill the result to a scratch file, cut into
//      the brick's eight octants.
//   3. Over a grid shifted by half a brick, whose cells straddle the bricks' seams: each cell
//      gathers the octants of the up to eight bricks around it, joins them at vertices with equal
//      keys, simplifies toward the final count (the cell's own boundary, in the middle of
//      bricks, locked), and streams the result into scratch files of vertices and faces.
//   4. The output is assembled from those (header, vertices, faces) and renamed into place.
//
// Scratch files live beside the output and are unlinked from the start, so they vanish however
// the process ends. The result depends on the brick plan (which seams are locked in which pass):
// deterministic for a given budget and thread count, not identical across budgets, and not equal
// to simplifying the whole mesh in core (docs/simplify.md measures the difference).
#pragma once

#include <filesystem>

#include "tiler/tiled_extract.h"

namespace isotile {

// Called by extract_tiled when options.simplify < 1. Throws InputError for DC quads (the result
// is triangles) and what extract_tiled throws.
TiledResult extract_tiled_simplified(VolumeSource& source, const TiledOptions& options,
                                     const std::filesystem::path& output);

}  // namespace isotile
