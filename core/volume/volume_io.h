// Reading volumes from files and from procedural field specs.
//
// Formats, chosen by name:
//   *.nii, *.nii.gz, *.mha, *.mhd, *.tif, *.tiff, DICOM files and directories, numbered TIFF
//   patterns (slice_%03d.tif)    through ITK (core/volume/itk_reader.h)
//   *.mrc, *.map, *.ccp4, *.mrcs MRC2014 / CCP4 maps
//   field:NAME:N                 procedural field (see procedural_fields.h), N^3 samples
//   *.nrrd, *.nhdr               NRRD through teem (attached or detached data, raw or gzip)
//   *.vdb                        OpenVDB: first float or double grid, active bounding box densified
//   *.raw, *.raw.gz, others      raw samples, x fastest; gzip'd when the name ends in .gz
// A raw file named NAME_XxYxZ_TYPE.raw[.gz] (e.g. bonsai_256x256x256_uint8.raw.gz) needs no
// options; otherwise RawOptions must give dims and type. Options given explicitly override what
// the name says.
//
// Every reader throws InputError (malformed content, wrong size, NaN/Inf samples) or IoError
// (cannot open or read) with a message naming the file and the problem.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/progress.h"
#include "core/volume/volume.h"

namespace isotile {

enum class Endian { Little, Big };

struct RawOptions {
  std::optional<Index3> dims;
  std::optional<ScalarType> type;
  std::optional<Vec3d> spacing;
  std::optional<Vec3d> origin;
  Endian endian = Endian::Little;
  std::string series;  // DICOM: the SeriesInstanceUID to read where a directory holds several
  // Told of the reading (Stage::Read, in bytes of samples; core/progress.h): raw files per 4 MiB
  // read or inflated, MRC per section; NRRD, VDB and ITK's formats are read by their libraries in
  // one call, reported at its start and end. Null: nobody listens.
  Progress* progress = nullptr;
};

// InputError where `raw` overrides the geometry with one that makes no mesh: a spacing that is
// not finite and above 0 (zero flattens the mesh, a negative one turns it inside out), an origin
// that is not finite; and where it gives a scalar type outside the enum. read_volume(),
// read_volume_header(), read_raw() and open_volume_source() check it first (the CLI's parsing
// refused such text; the library took the values).
void check_raw_overrides(const RawOptions& raw);

// What a raw file's name says, if it follows NAME_XxYxZ_TYPE.raw[.gz].
struct RawNameInfo {
  Index3 dims;
  ScalarType type;
};
std::optional<RawNameInfo> parse_raw_name(const std::string& path);

// Dims and type of a raw file: the options where given, else its name; InputError if unknown.
struct RawLayout {
  Index3 dims;
  ScalarType type;
};
RawLayout resolve_raw_layout(const std::string& path, const RawOptions& options);

// What an input is, from its name (and, for a directory or a file without a known extension,
// a look at its contents: TIFF slices, or DICOM's "DICM" marker).
enum class InputKind { Field, Raw, Nrrd, Vdb, Mrc, Nifti, MetaImage, Tiff, TiffStack, Dicom };
InputKind input_kind(const std::string& input);
const char* input_kind_name(InputKind kind);
bool is_itk_kind(InputKind kind);

// Samples stored plainly (uncompressed, unscaled) in one file from byte `offset` on, or a plane
// per file: such inputs are read box by box out of core.
struct PlainData {
  std::string file;
  std::uint64_t offset = 0;
  ScalarType type = ScalarType::UInt8;
  Index3 dims{0, 0, 0};
  Endian endian = Endian::Little;
  // The file ends with the samples, or (TIFF: the later pages' directories) may go on past them.
  bool bytes_after = false;
  // A stack of files (TIFF slices): plane z's samples at planes[z].offset in planes[z].file;
  // `file` and `offset` unused. Empty: one file.
  struct Plane {
    std::string file;
    std::uint64_t offset = 0;
  };
  std::vector<Plane> planes = {};
};

// InputError naming `file` when its `size` bytes are not `offset` + the samples of `type` and
// `dims` (shorter, or longer unless `bytes_after`): the check of every plainly stored input, in
// core (NRRD's raw data) and out of core (the tiler's raw source).
void check_plain_size(const std::string& file, std::uint64_t size, std::uint64_t offset,
                      ScalarType type, const Index3& dims, bool bytes_after = false);

// zlib's gzerror() text without the name it puts first (the path the stream was opened by, or
// "<fd:N>" for a gzdopen'd descriptor): the messages that quote it name the file already.
std::string gzerror_text(const std::string& opened_as, const char* message);

// Reads plainly stored samples (one file at an offset, or a stack of planes) into `volume`, of
// the layout's type and dims, in native byte order: the samples of a TIFF ITK's reader would not
// read right (32-bit integers), as the tiler reads them box by box.
void read_plain_data(const PlainData& plain, Volume& volume);

// An input's header: what `isotile info` shows besides the samples, and how the tiler can read
// it. Reading the header only costs little for every format (a DICOM series reads each file's
// header).
struct VolumeHeader {
  std::string
      format;  // "raw", "NRRD", "VDB", "MRC", "NIfTI", "MetaImage", "TIFF", "DICOM", "field"
  ScalarType type = ScalarType::Float32;
  Index3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  // The spacing's unit where the file names one isotile does not turn into mm (ImageJ's
  // calibration: "um", "micron", "nm"...); empty otherwise (mm for medical formats).
  std::string spacing_unit;
  Vec3d origin{0, 0, 0};
  std::optional<WorldFrame> world;
  bool rescaled = false;  // values are stored * slope + intercept
  double rescale_slope = 1;
  double rescale_intercept = 0;
  RescaleRange rescale_range;  // a DICOM series' slices' (the two above are the first slice's)
  std::string series_uid, series_description;  // DICOM
  std::optional<PlainData> plain;              // readable box by box
};
VolumeHeader read_volume_header(const std::string& input, const RawOptions& raw = {});

// Reads any supported input (dispatches on the name as described above).
Volume read_volume(const std::string& input, const RawOptions& raw = {});

// The individual readers.
Volume read_raw(const std::string& path, const RawOptions& options);  // plain or .gz
Volume read_nrrd(const std::string& path);
Volume read_vdb(const std::string& path);
// MRC2014 / CCP4 maps (core/volume/mrc_reader.cpp): header validated against the file size,
// axis order (mapc, mapr, maps), start fields, cell and origin honoured.
Volume read_mrc(const std::string& path, Progress* progress = nullptr);
VolumeHeader read_mrc_header(const std::string& path);

// An OpenVDB grid kept as its sparse tree and densified box by box (the out-of-core tiler reads
// .vdb input this way). Its volume is the grid's active bounding box; boxes are in that volume's
// sample indices. read_box writes box-extent samples of `type`, x fastest.
class VdbVolume {
 public:
  virtual ~VdbVolume() = default;
  virtual void read_box(const Box3& box, void* out) const = 0;
  ScalarType type = ScalarType::Float32;
  Index3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  Vec3d origin{0, 0, 0};
};
std::unique_ptr<VdbVolume> open_vdb(const std::string& path);

// Where a NRRD file keeps its samples, when that is one file of raw or gzip'd samples that can be
// read box by box; nullopt otherwise (several data files, other encodings, line skips).
struct NrrdDataLayout {
  std::string data_file;     // the file holding the samples (the NRRD itself when attached)
  std::uint64_t offset = 0;  // byte offset of the first sample (raw) or of the gzip stream
  bool gzip = false;
  Endian endian = Endian::Little;
  ScalarType type = ScalarType::UInt8;
  Index3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  Vec3d origin{0, 0, 0};
  std::optional<WorldFrame> world;
};
std::optional<NrrdDataLayout> nrrd_data_layout(const std::string& path);

// The largest magnitude a float64 sample may have. Past it the arithmetic on samples overflows
// double: at 9e307 the difference of two samples is infinite (vertices snapped onto samples, NaN
// normals), and from about 1e153 over the spacing the gradient's squared length is (zero or NaN
// normals). 1e100 keeps the gradient's square finite even over the finest spacing float32
// positions allow (1.4e-45); float32 samples never come near it.
inline constexpr double kLargestFloat64Sample = 1e100;

// "WHAT: N samples are KIND (first at x=.., y=.., z=..)": how check_finite names faulty samples,
// `first` their first one's global position.
std::string faulty_samples(const std::string& what, std::int64_t count, const char* kind,
                           const Index3& first);

// Throws InputError when a floating-point volume holds NaN or Inf samples, or float64 samples
// past kLargestFloat64Sample, saying how many and where the first one is (x, y, z). Integer
// volumes always pass.
void check_finite(const VolumeView& view, const std::string& what);

// Minimum and maximum sample value (0, 0 for an empty view; NaN samples are skipped, and an
// all-NaN view gives NaN, NaN; a zero bound is +0.0). One parallel pass
// (core/volume/finite_range.cpp).
std::pair<double, double> value_range(const VolumeView& view);

}  // namespace isotile
