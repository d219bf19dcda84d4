// Dispatch on the input's name, and the checks every reader shares.
#include "core/volume/volume_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <type_traits>
#include <unordered_map>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <fstream>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/volume/image_headers.h"
#include "core/volume/itk_reader.h"
#include "core/volume/numbered_files.h"
#include "core/volume/procedural_fields.h"

namespace isotile {

namespace {

// DICOM Part 10 files carry "DICM" after a 128-byte preamble.
bool has_dicom_marker(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;  // a pipe is read once
  std::ifstream f(path, std::ios::binary);
  char b[132];
  if (!f.read(b, sizeof b)) return false;
  return std::memcmp(b + 128, "DICM", 4) == 0;
}

// Formats isotile does not read, recognised by their content whatever the name says, so that a
// .vti or a .map.bz2 is named for what it is rather than taken for raw samples. Throws InputError
// saying what the file is and what to do with it.
void refuse_foreign_content(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    for (const char* marker : {".zarray", ".zgroup", "zarr.json"})
      if (std::filesystem::exists(std::filesystem::path(path) / marker, ec))
        throw InputError(
            path + ": a Zarr store (" + marker +
            "), which isotile does not read; export the array to raw samples (e.g. "
            "zarr.open(path)[:].tofile('out.raw') in Python) and pass --dims and --type");
    return;
  }
  // A pipe or FIFO (`<(zcat v.raw.gz)`) is read once: looking at its start would consume it.
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec)) return;
  std::ifstream f(path, std::ios::binary);
  if (!f) return;  // the reader names the problem
  char b[1032] = {};
  f.read(b, sizeof b);
  const std::size_t n = static_cast<std::size_t>(f.gcount());
  const auto at = [&](std::size_t offset, const char* magic, std::size_t len) {
    return n >= offset + len && std::memcmp(b + offset, magic, len) == 0;
  };
  const auto refuse = [&](const std::string& what, const std::string& todo) {
    throw InputError(path + ": " + what + ", which isotile does not read; " + todo);
  };
  // bzip2: "BZh", the block size, then a block or the end-of-stream marker.
  if (at(0, "BZh", 3) && n >= 10 && b[3] >= '1' && b[3] <= '9' &&
      (at(4, "\x31\x41\x59\x26\x53\x59", 6) || at(4, "\x17\x72\x45\x38\x50\x90", 6)))
    refuse("bzip2-compressed data", "decompress it first (bunzip2 -k FILE) and read the result");
  if (at(0,
         "\xfd"
         "7zXZ\0",
         6))
    refuse("xz-compressed data", "decompress it first (unxz -k FILE) and read the result");
  if (at(0, "\x28\xb5\x2f\xfd", 4))
    refuse("zstd-compressed data", "decompress it first (unzstd FILE) and read the result");
  // HDF5's signature lies at 0, 512, 1024, ... (after a user block).
  if (at(0, "\x89HDF\r\n\x1a\n", 8) || at(512, "\x89HDF\r\n\x1a\n", 8) ||
      at(1024, "\x89HDF\r\n\x1a\n", 8))
    refuse("an HDF5 file",
           "export the dataset to raw samples (h5dump -d /DATASET -b LE -o out.raw FILE) and pass "
           "--dims and --type");
  // A NIfTI or Analyze 7.5 header beside its .img: sizeof_hdr 348 in either byte order, and
  // NIfTI's "ni1" magic where it has one. Taken for a raw file by its name, it got the raw
  // name's message (pass --dims and --type, which would drop its geometry).
  // (By the name too: a raw volume may start with those bytes.)
  if (ends_with_ci(path, ".hdr") && n >= 348 &&
      (at(0, "\x5c\x01\0\0", 4) || at(0, "\0\0\x01\x5c", 4)))
    refuse(at(344, "ni1\0", 4) ? "a NIfTI header whose samples are in a separate .img file"
                               : "an Analyze 7.5 header (.hdr, samples in a separate .img file)",
           "convert the pair to a single .nii (e.g. nibabel.save(nibabel.load(HDR), 'out.nii'))");
  if (at(0, "# vtk DataFile Version", 22))
    refuse("a legacy VTK file",
           "convert it to MetaImage or NIfTI (e.g. ParaView's Save Data as .mha, or VTK's "
           "vtkMetaImageWriter)");
  const std::string_view head(b, n);
  // A mesh chosen where a volume belongs (the MeshLab filter's file dialog shows every file):
  // by its PLY or OFF header, or a mesh format's extension.
  const bool mesh_name = ends_with_ci(path, ".ply") || ends_with_ci(path, ".obj") ||
                         ends_with_ci(path, ".stl") || ends_with_ci(path, ".off");
  if (mesh_name || head.starts_with("ply\n") || head.starts_with("ply\r\n") ||
      head.starts_with("OFF\n") || head.starts_with("OFF\r\n"))
    throw InputError(path +
                     ": a mesh, not a volume: extraction reads samples on a grid (`isotile "
                     "quality`, `simplify` and `render` read meshes)");
  if ((head.starts_with("<?xml") || head.starts_with("<VTKFile")) &&
      head.find("<VTKFile") != std::string_view::npos)
    refuse("a VTK XML file",
           "convert it to MetaImage or NIfTI (e.g. ParaView's Save Data as .mha, or VTK's "
           "vtkMetaImageWriter)");
}

bool is_tiff_name(const std::string& s) {
  return ends_with_ci(s, ".tif") || ends_with_ci(s, ".tiff");
}

ItkInput itk_input(const std::string& input, InputKind kind, const RawOptions& raw) {
  ItkInput in;
  in.path = input;
  in.series = raw.series;
  in.spacing_given = raw.spacing.has_value();
  switch (kind) {
    case InputKind::Nifti:
      in.kind = ItkInput::Kind::Nifti;
      break;
    case InputKind::MetaImage:
      in.kind = ItkInput::Kind::MetaImage;
      break;
    case InputKind::Tiff:
      in.kind = ItkInput::Kind::Tiff;
      break;
    case InputKind::TiffStack:
      in.kind = ItkInput::Kind::TiffStack;
      break;
    default:
      in.kind = ItkInput::Kind::Dicom;
      break;
  }
  return in;
}

// The calibration of a stack of slices: the one its slices share, read as ImageJ's image
// sequence import reads it (the pixel size of the slices, the voxel depth theirs too, or 1 unit
// where a slice says none), or none where no slice has one. Slices calibrated differently, or
// some not at all, are refused: which of them holds is anyone's guess.
std::optional<ImageJSpacing> stack_calibration(
    const std::string& input,
    const std::map<std::string, std::optional<ImageJSpacing>>& calibrations) {
  const auto text = [](const std::optional<ImageJSpacing>& c) {
    if (!c) return std::string("uncalibrated");
    return short_number(c->spacing[0]) + ", " + short_number(c->spacing[1]) + ", " +
           short_number(c->spacing[2]) + (c->unit.empty() ? "" : " " + c->unit);
  };
  const auto same = [](const std::optional<ImageJSpacing>& a,
                       const std::optional<ImageJSpacing>& b) {
    return a.has_value() == b.has_value() &&
           (!a || (a->spacing == b->spacing && a->unit == b->unit));
  };
  if (calibrations.empty()) return std::nullopt;
  const auto& [first_file, first] = *calibrations.begin();
  for (const auto& [file, c] : calibrations)
    if (!same(c, first))
      throw InputError(input + ": its slices are calibrated differently (" + first_file + ": " +
                       text(first) + "; " + file + ": " + text(c) +
                       "); give the spacing with --spacing X,Y,Z");
  return first;
}

// Checks made before ITK or GDCM sees the file (they are not hardened against malformed input).
// `raw`: what the user gave; a spacing given makes the slices' calibrations moot.
ImageHeaderCheck check_before_itk(const std::string& input, InputKind kind, const RawOptions& raw) {
  if (kind == InputKind::Nifti) {
    ImageHeaderCheck check = check_nifti_header(input);
    if (!check.unknown_spacing.empty() && !raw.spacing) throw InputError(check.unknown_spacing);
    return check;
  }
  if (kind == InputKind::MetaImage) return check_metaimage_header(input);
  if (kind == InputKind::Tiff) {
    ImageHeaderCheck check;
    TiffCheck tiff = check_tiff_file(input);
    check.plain = std::move(tiff.plain);
    check.calibration = std::move(tiff.calibration);
    check.imagej_planes = tiff.imagej_planes;
    return check;
  }
  if (kind == InputKind::TiffStack) {
    ImageHeaderCheck check;
    // Each slice's ImageJ calibration, by file name. ImageJ's image sequences carry it in every
    // slice, and ITK reads none of it: a stack of 0.5 um pixels was read at 1, 1, 1.
    std::map<std::string, std::optional<ImageJSpacing>> calibrations;
    const auto slice = [&](const std::string& file) {
      TiffCheck tiff = check_tiff_file(file);
      if (tiff.plain) check.plain_slices.push_back(*tiff.plain);
      calibrations[file] = std::move(tiff.calibration);
    };
    std::error_code ec;
    if (std::filesystem::is_directory(input, ec)) {
      for (const auto& e : std::filesystem::directory_iterator(input, ec))
        if (e.is_regular_file(ec) && is_tiff_name(e.path().string())) slice(e.path().string());
    } else {
      for (const std::string& name : numbered_files(input)) slice(name);  // as ITK takes them
    }
    if (!raw.spacing) check.calibration = stack_calibration(input, calibrations);
    return check;
  }
  if (kind == InputKind::Dicom) check_dicom_input(input);
  return {};
}

// A TIFF stack whose every slice, in the order ITK stacks them, is one plane stored plainly, of
// the type ITK reads and in one byte order: read plane by plane out of core.
std::optional<PlainData> stacked_slices(const std::vector<PlainData>& slices,
                                        const ItkImageInfo& info) {
  if (info.files.size() != static_cast<std::size_t>(info.dims[2]) || info.files.empty())
    return std::nullopt;
  std::unordered_map<std::string, const PlainData*> by_name;
  for (const PlainData& p : slices) by_name.emplace(p.file, &p);
  PlainData out;
  out.type = info.type;
  out.dims = info.dims;
  for (const std::string& file : info.files) {
    const auto found = by_name.find(file);
    const PlainData* s = found == by_name.end() ? nullptr : found->second;
    if (!s || s->type != info.type || s->dims[0] != info.dims[0] || s->dims[1] != info.dims[1] ||
        s->dims[2] != 1 || (file != info.files.front() && s->endian != out.endian))
      return std::nullopt;
    out.endian = s->endian;
    out.planes.push_back({file, s->offset});
  }
  return out;
}

// Where the samples of an ITK input lie plainly (for the tiler to read box by box, and for TIFF
// to be read so in core too), from the checks made before ITK and ITK's own header.
std::optional<PlainData> plain_layout(const std::string& input, InputKind kind,
                                      const ImageHeaderCheck& check, const ItkImageInfo& info) {
  std::optional<PlainData> plain;
  if (check.plain && check.plain->type == info.type && check.plain->dims == info.dims)
    plain = check.plain;
  if (kind == InputKind::TiffStack) plain = stacked_slices(check.plain_slices, info);
  // ITK 5.2's TIFF reader takes 32-bit integer pages for a volume but reads none of their samples
  // (it has no code for them): the buffer stays as it was, a different mesh on each run. isotile
  // reads them itself where they are stored plainly.
  if ((kind == InputKind::Tiff || kind == InputKind::TiffStack) && !plain &&
      (info.type == ScalarType::Int32 || info.type == ScalarType::UInt32))
    throw InputError(input +
                     ": 32-bit integer TIFF samples are read only when stored "
                     "uncompressed, in strips that follow each other (as ImageJ writes "
                     "them), and alike in every file of a stack; ITK's TIFF reader cannot "
                     "read them otherwise. Save them so, or as 16-bit or 32-bit float");
  return plain;
}

// The spacing and world frame of an ITK input: ITK's, with what the checks before it read that
// ITK does not (a TIFF's ImageJ calibration, NIfTI's units applied to the origin too).
struct ItkGeometry {
  Vec3d spacing, origin;
  WorldFrame world;
};
ItkGeometry itk_geometry(const ImageHeaderCheck& check, const ItkImageInfo& info) {
  ItkGeometry g;
  g.spacing = check.calibration ? check.calibration->spacing : info.spacing;
  for (int a = 0; a < 3; ++a) g.origin[a] = info.origin[a] * check.origin_scale;
  g.world = WorldFrame{g.origin, info.direction};
  return g;
}

// ITK's header of an input, or, for an ImageJ stack in one page directory (which ITK reads as
// one page), the header its checked layout gives: origin 0 and no rotation, as ITK gives a TIFF.
ItkImageInfo itk_info(const std::string& input, InputKind kind, const RawOptions& raw,
                      const ImageHeaderCheck& check) {
  if (!check.imagej_planes || !check.plain) return read_itk_info(itk_input(input, kind, raw));
  ItkImageInfo info;
  info.format = "TIFF";
  info.type = check.plain->type;
  info.dims = check.plain->dims;
  return info;
}

// Options that only a raw file can use would otherwise be dropped without a word.
void reject_raw_only_options(const std::string& input, const RawOptions& raw, const char* kind) {
  if (raw.dims || raw.type || raw.endian == Endian::Big)
    throw InputError(input + ": --dims, --type and big-endian apply only to raw files; a " + kind +
                     " says its own");
}

struct NonFinite {
  std::int64_t count = 0;
  // Position of the first one in x-fastest order, as a linear index into the view; -1 if none.
  std::int64_t first = -1;
};

// Samples for which `bad` holds, counted in one parallel pass.
template <class T, class Bad>
NonFinite count_samples(const VolumeView& view, Bad bad) {
  const T* data = view.typed<T>();
  const Index3& d = view.dims;
  return tbb::parallel_reduce(
      tbb::blocked_range<std::int64_t>(0, d[2]), NonFinite{},
      [&](const tbb::blocked_range<std::int64_t>& r, NonFinite acc) {
        for (std::int64_t k = r.begin(); k != r.end(); ++k)
          for (std::int64_t j = 0; j < d[1]; ++j) {
            const T* row = data + view.offset(0, j, k);
            for (std::int64_t i = 0; i < d[0]; ++i) {
              if (!bad(row[i * view.strides[0]])) continue;
              if (acc.count++ == 0) acc.first = (k * d[1] + j) * d[0] + i;
            }
          }
        return acc;
      },
      [](NonFinite a, const NonFinite& b) {
        a.count += b.count;
        if (a.first < 0 || (b.first >= 0 && b.first < a.first)) a.first = b.first;
        return a;
      });
}

std::string override_text(const Vec3d& v) {
  return number_text(v[0]) + "," + number_text(v[1]) + "," + number_text(v[2]);
}

// --spacing and --origin replace what the file says; the origin moves the world frame too.
void apply_overrides(const RawOptions& raw, Vec3d& spacing, Vec3d& origin,
                     std::optional<WorldFrame>& world) {
  if (raw.spacing) spacing = *raw.spacing;
  if (raw.origin) {
    origin = *raw.origin;
    if (world) world->origin = *raw.origin;
  }
}

void apply_overrides(const RawOptions& raw, Volume& volume) {
  Vec3d spacing = volume.spacing(), origin = volume.origin();
  std::optional<WorldFrame> world = volume.world();
  apply_overrides(raw, spacing, origin, world);
  volume.set_spacing(spacing);
  volume.set_origin(origin);
  volume.set_world(world);
}

}  // namespace

void check_raw_overrides(const RawOptions& raw) {
  if (raw.spacing)
    for (const double v : *raw.spacing)
      if (!(std::isfinite(v) && v > 0))
        throw InputError("--spacing must be three finite numbers above 0, got " +
                         override_text(*raw.spacing));
  if (raw.origin)
    for (const double v : *raw.origin)
      if (!std::isfinite(v))
        throw InputError("--origin must be three finite numbers, got " +
                         override_text(*raw.origin));
  if (raw.type) scalar_size(*raw.type);  // throws for a type outside the enum
}

InputKind input_kind(const std::string& input) {
  if (parse_field_spec(input)) return InputKind::Field;
  refuse_foreign_content(input);
  std::error_code ec;
  if (std::filesystem::is_directory(input, ec)) {
    for (const auto& e : std::filesystem::directory_iterator(input, ec))
      if (e.is_regular_file() && is_tiff_name(e.path().string())) return InputKind::TiffStack;
    return InputKind::Dicom;
  }
  // A name with a % is a pattern of numbered slices, unless it names a file.
  if (is_tiff_name(input))
    return input.find('%') != std::string::npos && !std::filesystem::is_regular_file(input, ec)
               ? InputKind::TiffStack
               : InputKind::Tiff;
  const std::string ext = lower_extension(input);
  if (ext == ".nrrd" || ext == ".nhdr") return InputKind::Nrrd;
  if (ext == ".vdb") return InputKind::Vdb;
  if (ext == ".mrc" || ext == ".map" || ext == ".ccp4" || ext == ".mrcs") return InputKind::Mrc;
  for (const char* mrc : {".mrc.gz", ".map.gz", ".ccp4.gz", ".mrcs.gz"})
    if (ends_with_ci(input, mrc)) return InputKind::Mrc;
  if (ext == ".nii" || ends_with_ci(input, ".nii.gz")) return InputKind::Nifti;
  if (ext == ".mha" || ext == ".mhd") return InputKind::MetaImage;
  if (ext == ".dcm" || ext == ".ima") return InputKind::Dicom;
  if (!parse_raw_name(input) && has_dicom_marker(input)) return InputKind::Dicom;
  return InputKind::Raw;
}

const char* input_kind_name(InputKind kind) {
  switch (kind) {
    case InputKind::Field:
      return "field";
    case InputKind::Raw:
      return "raw";
    case InputKind::Nrrd:
      return "NRRD";
    case InputKind::Vdb:
      return "VDB";
    case InputKind::Mrc:
      return "MRC";
    case InputKind::Nifti:
      return "NIfTI";
    case InputKind::MetaImage:
      return "MetaImage";
    case InputKind::Tiff:
    case InputKind::TiffStack:
      return "TIFF";
    case InputKind::Dicom:
      return "DICOM";
  }
  return "?";
}

bool is_itk_kind(InputKind kind) {
  return kind == InputKind::Nifti || kind == InputKind::MetaImage || kind == InputKind::Tiff ||
         kind == InputKind::TiffStack || kind == InputKind::Dicom;
}

VolumeHeader read_volume_header(const std::string& input, const RawOptions& raw) {
  check_raw_overrides(raw);
  const InputKind kind = input_kind(input);
  VolumeHeader h;
  h.format = input_kind_name(kind);
  if (kind != InputKind::Raw) reject_raw_only_options(input, raw, h.format.c_str());
  if (!raw.series.empty() && kind != InputKind::Dicom)
    throw InputError(input + ": --series applies to DICOM only");
  if (kind == InputKind::Mrc) {
    h = read_mrc_header(input);
  } else if (is_itk_kind(kind)) {
    const ImageHeaderCheck check = check_before_itk(input, kind, raw);
    const ItkImageInfo info = itk_info(input, kind, raw, check);
    h.type = info.type;
    h.dims = info.dims;
    const ItkGeometry g = itk_geometry(check, info);
    h.spacing = g.spacing;
    if (check.calibration) h.spacing_unit = check.calibration->unit;
    h.origin = g.origin;
    h.world = g.world;
    h.rescaled = info.rescaled || info.rescale_range.per_slice() || check.rescaled;
    h.rescale_slope = check.rescaled ? check.rescale_slope : info.rescale_slope;
    h.rescale_intercept = check.rescaled ? check.rescale_intercept : info.rescale_intercept;
    h.rescale_range = info.rescale_range;
    h.series_uid = info.series_uid;
    h.series_description = info.series_description;
    h.plain = plain_layout(input, kind, check, info);
  } else if (kind == InputKind::Nrrd) {
    if (const std::optional<NrrdDataLayout> d = nrrd_data_layout(input)) {
      h.type = d->type;
      h.dims = d->dims;
      h.spacing = d->spacing;
      h.origin = d->origin;
      h.world = d->world;
      if (!d->gzip) h.plain = PlainData{d->data_file, d->offset, d->type, d->dims, d->endian};
    } else {
      const Volume v = read_nrrd(input);
      h.type = v.type();
      h.dims = v.dims();
      h.spacing = v.spacing();
      h.origin = v.origin();
      h.world = v.world();
    }
  } else {
    // Fields, raw and VDB: their headers are their names or need the data anyway.
    const Volume v = read_volume(input, raw);
    h.type = v.type();
    h.dims = v.dims();
    h.spacing = v.spacing();
    h.origin = v.origin();
    return h;
  }
  apply_overrides(raw, h.spacing, h.origin, h.world);
  if (raw.spacing) h.spacing_unit.clear();
  return h;
}

void check_plain_size(const std::string& file, std::uint64_t size, std::uint64_t offset,
                      ScalarType type, const Index3& dims, bool bytes_after) {
  const std::uint64_t need = checked_volume_bytes(type, dims);
  if (size == offset + need || (bytes_after && size > offset + need)) return;
  throw InputError(file + ": file holds " + std::to_string(size) + " bytes but " +
                   std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                   std::to_string(dims[2]) + " " + std::string(scalar_name(type)) +
                   " samples need " + std::to_string(need) +
                   (offset ? " after " + std::to_string(offset) + " header bytes" : "") +
                   (size < offset + need ? " (too short)" : " (too long)"));
}

Volume read_volume(const std::string& input, const RawOptions& raw) {
  check_raw_overrides(raw);
  if (const std::optional<FieldSpec> spec = parse_field_spec(input)) {
    reject_raw_only_options(input, raw, "procedural field");
    if (!raw.series.empty()) throw InputError(input + ": --series applies to DICOM only");
    // --spacing and --origin place a field's grid as they do a file's (and as the streamed
    // source does, so that in core and out of core give the same file).
    Volume volume = make_field_volume(*spec);
    apply_overrides(raw, volume);
    return volume;
  }
  const InputKind kind = input_kind(input);
  if (!raw.series.empty() && kind != InputKind::Dicom)
    throw InputError(input + ": --series applies to DICOM only");
  if (kind == InputKind::Raw) return read_raw(input, raw);

  reject_raw_only_options(input, raw, input_kind_name(kind));
  Volume volume;
  // NRRD, VDB and ITK's libraries read in one call: reported at its start and its end only.
  if (kind != InputKind::Mrc) progress_begin(raw.progress, Stage::Read, 1);
  if (kind == InputKind::Mrc) {
    volume = read_mrc(input, raw.progress);
  } else if (kind == InputKind::Nrrd) {
    volume = read_nrrd(input);
  } else if (kind == InputKind::Vdb) {
    volume = read_vdb(input);
  } else {
    const ImageHeaderCheck check = check_before_itk(input, kind, raw);
    verify_compressed(check);
    verify_plain_floats(check);
    const ItkInput in = itk_input(input, kind, raw);
    const ItkImageInfo info = itk_info(input, kind, raw, check);
    const ItkGeometry g = itk_geometry(check, info);
    volume = Volume(info.type, info.dims, g.spacing, g.origin);
    volume.set_world(g.world);
    volume.set_series(info.series_uid, info.series_description);
    const std::optional<PlainData> plain = plain_layout(input, kind, check, info);
    // A plainly stored TIFF is read as out of core reads it (ITK's reader cannot read all of
    // them, above), and so are a NIfTI file's plain floating-point samples: ITK's nifti library
    // turns NaN and Inf into 0, and a volume refused with --memory was meshed in core, exit 0.
    // The other formats' plain samples are ITK's to read.
    if (plain && (kind == InputKind::Tiff || kind == InputKind::TiffStack ||
                  (kind == InputKind::Nifti && is_floating(info.type))))
      read_plain_data(*plain, volume);
    else
      read_itk_data(in, info, volume.bytes());
    if (check.text) verify_text_samples(*check.text, volume.bytes(), volume.dims());
    check_finite(volume.view(), input);
  }
  if (kind != InputKind::Mrc) progress_advance(raw.progress);
  apply_overrides(raw, volume);
  return volume;
}

std::string faulty_samples(const std::string& what, std::int64_t count, const char* kind,
                           const Index3& first) {
  return what + ": " + std::to_string(count) + (count == 1 ? " sample is " : " samples are ") +
         kind + " (first at x=" + std::to_string(first[0]) + ", y=" + std::to_string(first[1]) +
         ", z=" + std::to_string(first[2]) + ")";
}

void check_finite(const VolumeView& view, const std::string& what) {
  if (!is_floating(view.type) || view.sample_count() <= 0) return;
  // At the first sample's global position.
  const auto found = [&](const NonFinite& n, const char* kind) {
    const std::int64_t i = n.first % view.dims[0];
    const std::int64_t j = n.first / view.dims[0] % view.dims[1];
    const std::int64_t k = n.first / view.dims[0] / view.dims[1];
    return faulty_samples(what, n.count, kind,
                          {view.box.lo[0] + i, view.box.lo[1] + j, view.box.lo[2] + k});
  };
  const auto non_finite = [](auto v) { return !std::isfinite(v); };
  const auto refuse_non_finite = [&](const NonFinite& n) {
    if (n.count > 0) throw InputError(found(n, "NaN or Inf") + "; isosurfaces need finite values");
  };
  if (view.type == ScalarType::Float32) {
    refuse_non_finite(count_samples<float>(view, non_finite));
    return;
  }
  // Float64: one pass finds both faults (NaN fails the comparison too); only a volume that has
  // one is read again, to tell which.
  const NonFinite out = count_samples<double>(
      view, [](double v) { return !(std::fabs(v) <= kLargestFloat64Sample); });
  if (out.count == 0) return;
  refuse_non_finite(count_samples<double>(view, non_finite));
  throw InputError(found(out, "past +-1e100") +
                   "; float64 values that large overflow the differences and gradients an "
                   "isosurface is computed from: scale the samples");
}

// Through open_vdb, which the isotile program resolves to a module it loads on first use
// (tiler/reader_modules.cpp).
Volume read_vdb(const std::string& path) {
  const std::unique_ptr<VdbVolume> vdb = open_vdb(path);
  Volume volume(vdb->type, vdb->dims, vdb->spacing, vdb->origin);
  vdb->read_box({{0, 0, 0}, vdb->dims}, volume.bytes());
  check_finite(volume.view(), path);
  return volume;
}

}  // namespace isotile
