// Checks of NIfTI and MetaImage headers made before ITK sees the file (ITK's readers are not
// hardened against malformed input: a header may claim more data than the file holds, or sizes
// that overflow), and where their samples lie when they are stored plainly, so that the tiler
// can read them box by box.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/volume/imagej_description.h"
#include "core/volume/text_samples.h"
#include "core/volume/volume_io.h"

namespace isotile {

struct ImageHeaderCheck {
  // NIfTI's floating-point samples, checked for NaN and Inf before ITK reads them: its nifti
  // library turns them into 0 (a volume whose samples it should refuse, meshed, exit 0).
  struct Floats {
    ScalarType type = ScalarType::Float32;
    Index3 dims{0, 0, 0};
    std::uint64_t at = 0;  // where the samples start in the (inflated) file
    bool swap = false;     // stored in the other byte order
  };
  std::optional<PlainData> plain;  // uncompressed, unscaled samples in one file
  // TIFF stacks: each slice file stored plainly, by its name (as the stack lists it).
  std::vector<PlainData> plain_slices;
  std::optional<ImageJSpacing> calibration;  // a TIFF's, which ITK does not read (TiffCheck)
  bool imagej_planes = false;                // TiffCheck's: read from `plain` without ITK
  bool rescaled = false;                     // NIfTI's scl_slope/scl_inter change the values
  double rescale_slope = 1;
  double rescale_intercept = 0;
  // Compressed samples, which only inflating them shows to be all there (verify_compressed).
  struct Compressed {
    std::string file;              // holding the compressed stream
    std::uint64_t offset = 0;      // where the stream starts in it
    std::uint64_t need = 0;        // bytes it must inflate to
    bool whole_gzip = false;       // NIfTI .nii.gz: the file is one gzip stream, header included,
                                   // and may run on past `need`; else a zlib stream of exactly need
    std::string what;              // the samples, e.g. "256x256x133 uint8 samples"
    bool members = false;          // gzip of exactly `need` in one or more members (NRRD)
    std::uint64_t limit = 0;       // the stream's compressed bytes when the header says (else 0)
    std::optional<Floats> floats;  // checked as they inflate
  };
  std::optional<Compressed> compressed;
  // Uncompressed floating-point samples that ITK reads (rescaled ones), checked in the file.
  struct PlainFloats {
    std::string file;
    Floats floats;
  };
  std::optional<PlainFloats> plain_floats;
  // Samples written as text (MetaImage's BinaryData = False), checked once ITK has read them.
  std::optional<TextSamples> text;
  // NIfTI's xyzt_units in millimetres per unit (1000 for metres, 0.001 for microns). ITK scales
  // the spacing by it but not the origin: the caller scales the origin, else a micron file's
  // mesh lay 1000 times too far from 0 for its size.
  double origin_scale = 1;
  // Set where the header gives no spacing along an axis of more than one sample (NIfTI's pixdim
  // 0 without an sform, which ITK reads as 1): the message, refused unless --spacing is given.
  std::string unknown_spacing;
};

// Throw InputError naming the file and the field at fault, IoError when it cannot be read.
ImageHeaderCheck check_nifti_header(const std::string& path);
ImageHeaderCheck check_metaimage_header(const std::string& path);

// DICOM Part 10 files (with the "DICM" marker), walked element by element before GDCM sees them:
// every element must lie within the file and the pixel data must hold the Rows x Columns x
// samples x frames its header says (GDCM reads a cut-off slice as zeros with a warning only, and
// aborts on some cut-off headers). Files without the marker are left to GDCM, unless `given` (the
// input named by the user), when they must parse as an implicit-VR data set, or unless GDCM's
// scan of a folder would pass them by while they are named as DICOM (.dcm, .ima, .dicom) or
// are empty without an extension: slices cut short, refused (the series was read without them).
void check_dicom_file(const std::string& path, bool given = false);
// The same for the DICOM files of a series input: the directory's files, or those beside a file.
// A file there that cannot be read is refused too (GDCM passes it by).
void check_dicom_input(const std::string& input);

// TIFF files (classic and BigTIFF), every page's directory walked before ITK sees them: the
// directories, their values and every strip or tile must lie within the file, and uncompressed
// pages must hold the samples their size says.
struct TiffCheck {
  // Where the samples lie when every page stores them uncompressed, one gray sample per pixel,
  // top row first, in strips that run on from page to page (as ImageJ writes stacks): the pages
  // as planes of a raw volume.
  std::optional<PlainData> plain;
  // ImageJ's calibration, which ITK does not read (it takes the resolution tags only where their
  // unit is the inch or the centimetre).
  std::optional<ImageJSpacing> calibration;
  // One page directory that ImageJ's description gives more images (its layout past 4 GiB):
  // `plain` holds them all, and ITK, which sees one page, is not asked.
  bool imagej_planes = false;
};
TiffCheck check_tiff_file(const std::string& path);

// Inflates a checked header's compressed samples (without keeping them) and throws InputError,
// naming the file, the bytes expected and those found, when the stream is cut off, corrupt, or
// does not hold exactly the samples (ITK's readers would otherwise fill the rest with zeros and
// say nothing, or print a warning only).
void verify_compressed(const ImageHeaderCheck& check);

// Reads a checked header's uncompressed floating-point samples that ITK will read (without
// keeping them) and throws InputError, as check_finite does, where one is NaN or Inf.
void verify_plain_floats(const ImageHeaderCheck& check);

}  // namespace isotile
