// Volumes read box by box, for out-of-core extraction: a brick's samples are read when the brick
// is extracted, and no source holds the whole volume unless its format leaves no other way.
//
//   field:NAME:N       evaluated per box
//   raw (plain)        positioned reads (pread) of the box's rows
//   raw .gz            decompressed in order: boxes must come in ascending z and span whole x-y
//                      slabs (the planner is told so by sequential()); each pass restarts the
//                      stream
//   NRRD               the header through teem; one raw data file (attached or detached) by
//                      positioned reads, one gzip data file in slabs; anything else read whole
//   VDB                the sparse tree in memory, each box densified from it
//   MRC, NIfTI (.nii), MetaImage, when stored plainly (uncompressed, unscaled; MRC in X, Y, Z
//                      axis order)  positioned reads like raw files
//   anything else (gzip'd NIfTI, compressed MetaImage, TIFF, DICOM, rescaled NIfTI, MRC in
//                      another axis order)  read whole: in_memory() says so
#pragma once

#include <memory>
#include <string>

#include "core/volume/volume.h"
#include "core/volume/volume_io.h"

namespace isotile {

class VolumeSource {
 public:
  virtual ~VolumeSource() = default;

  ScalarType type = ScalarType::Float32;
  Index3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  Vec3d origin{0, 0, 0};
  std::optional<WorldFrame> world;  // see VolumeView::world

  // True when boxes can only be read as whole x-y slabs in ascending z (per pass; rewind() starts
  // a new pass).
  virtual bool sequential() const { return false; }
  virtual void rewind() {}
  // Sequential sources: consecutive boxes of a pass share up to this many z-planes (2 halo + 1
  // for bricks grown by their halo), which the source keeps from one box to the next.
  virtual void set_overlap(std::int64_t /*planes*/) {}
  // Whether the whole volume is held in memory anyway (its bytes count as resident).
  virtual bool in_memory() const { return false; }
  // Bytes the source holds while reading, whatever the box (a decompressor's buffers).
  virtual std::uint64_t buffer_bytes() const { return 0; }
  // Reads global box `box` into `out` (box extent samples of `type`, x fastest). Throws IoError
  // or InputError (e.g. NaN samples) naming the input.
  virtual void read(const Box3& box, void* out) = 0;
  // Throws InputError naming a file the source reads from that changed since it was opened (its
  // size or modification time; or, for files opened anew at each read, which file the name
  // holds). An out-of-core run reads its input twice (count, then extract): a change between or
  // within the passes would mix old and new samples in one mesh, or break its counts.
  virtual void check_unchanged() const {}

  std::string name;
  std::string series_uid, series_description;  // a DICOM series' (VolumeHeader's); else empty
};

// Opens any input read_volume() accepts. Spacing and origin in `raw` override the file's.
// `memory_budget` (0: none): a source that must read the whole volume refuses, with a message
// saying so, when the volume alone would not fit it.
std::unique_ptr<VolumeSource> open_volume_source(const std::string& input, const RawOptions& raw,
                                                 std::uint64_t memory_budget = 0);

// A view of `data` (which holds `box` of the source's volume, dense) placed in the global grid.
VolumeView brick_view(const VolumeSource& source, const Box3& box, const void* data);

}  // namespace isotile
