// Macet's relaxation of sign-pinned samples (MacetOptions::relax), internal to core/.
//
// Macet keeps every crossing on the trilinear interpolant between displaced grid vertices, and a
// grid vertex may not cross the surface. A sample that sits in a one-sample-thin sheet, rod or
// speck, with the other side of the surface close to it along both directions of one axis, can
// then hardly move (any move flips its side), and the triangles joining its tiny cap of crossings
// to the rest of the surface are slivers: they cap bonsai's minimum radius ratio near 0.1 (docs/
// macet.md). Relaxation trades accuracy for those triangles: such a sample's value is moved away
// from the isovalue until the crossings on its edges lie at least `relax` edge lengths from it,
// and never moves one of them by more than `relax` edge lengths. Signs are kept, so the
// classification and the topology stay MC's, and the surface moves by at most `relax` voxels,
// only next to pinned samples.
//
// Pinned: along some axis both neighbours lie on the other side of the isovalue and both
// crossings (linear along the grid edge) are closer than `relax` to the sample.
#pragma once

#include <vector>

#include "core/extract/macet_field.h"
#include "core/volume/volume.h"

namespace isotile::detail {

// The samples of `view` as doubles (x fastest, the view's dims), pinned ones relaxed. A sample
// whose six neighbours are not all in the view (where the volume goes on) is kept as it is:
// brick mode grows the halo by one so that such samples never reach an emitted result.
ScratchVector<double> relax_pinned_samples(const VolumeView& view, double iso, double relax);

}  // namespace isotile::detail
