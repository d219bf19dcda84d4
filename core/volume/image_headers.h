// Checks of NIfTI and MetaImage headers made before ITK sees the file (ITK's readers are not
// hardened against malformed input: a header may claim more data than the file holds, or sizes
// that overflow), and where their samples lie when they are stored plainly, so that the tiler
// can read them box by box.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/volume/volume_io.h"

namespace isotile {

struct ImageHeaderCheck {
  std::optional<PlainData> plain;  // uncompressed, unscaled samples in one file
  bool rescaled = false;           // NIfTI's scl_slope/scl_inter change the values
  double rescale_slope = 1;
  double rescale_intercept = 0;
};

// Throw InputError naming the file and the field at fault, IoError when it cannot be read.
ImageHeaderCheck check_nifti_header(const std::string& path);
ImageHeaderCheck check_metaimage_header(const std::string& path);

}  // namespace isotile
