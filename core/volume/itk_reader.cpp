// ITK's image IO behind plain buffers. The ImageIO classes are used directly, without ITK's
// templated reader pipeline: headers and samples go straight into the caller's buffer (no second
// copy of the volume), and this file stays cheap to compile.
#include "core/volume/itk_reader.h"
#include "core/volume/dicom_frames.h"
#include "core/volume/numbered_files.h"
#include "core/volume/slice_stack.h"

#include <gdcmTrace.h>
#include <itkGDCMImageIO.h>
#include <itkGDCMSeriesFileNames.h>
#include <itkImageIOBase.h>
#include <itkMetaDataObject.h>
#include <itkMetaImageIO.h>
#include <itkNiftiImageIO.h>
#include <itkTIFFImageIO.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include "core/errors.h"
#include "core/file_names.h"

// ITK's own copy of libtiff (libitktiff) warns on stderr about every private tag it does not
// know, e.g. ImageJ's 50838/50839 on each page; its header is not installed.
extern "C" {
using ItkTiffHandler = void (*)(const char*, const char*, va_list);
ItkTiffHandler itk_TIFFSetWarningHandler(ItkTiffHandler);
}

namespace isotile {

namespace {

namespace fs = std::filesystem;
using IOComponent = itk::IOComponentEnum;

void quiet_libtiff() {
  static std::once_flag once;
  std::call_once(once, [] { itk_TIFFSetWarningHandler(nullptr); });
}

// ITK's exception text spans several lines (file, line, location, description): the CLI prints
// one, so keep the description.
std::string itk_message(const itk::ExceptionObject& e) {
  std::string text = e.GetDescription() ? e.GetDescription() : e.what();
  for (char& c : text)
    if (c == '\n' || c == '\r') c = ' ';
  while (!text.empty() && text.back() == ' ') text.pop_back();
  return text;
}

std::size_t type_size(ScalarType t) {
  switch (t) {
    case ScalarType::Int8:
    case ScalarType::UInt8:
      return 1;
    case ScalarType::Int16:
    case ScalarType::UInt16:
      return 2;
    case ScalarType::Int32:
    case ScalarType::UInt32:
    case ScalarType::Float32:
      return 4;
    case ScalarType::Float64:
      return 8;
  }
  return 1;
}

ScalarType scalar_of(IOComponent c, std::size_t size, const std::string& what) {
  switch (c) {
    case IOComponent::UCHAR:
      return ScalarType::UInt8;
    case IOComponent::CHAR:
      return ScalarType::Int8;
    case IOComponent::USHORT:
      return ScalarType::UInt16;
    case IOComponent::SHORT:
      return ScalarType::Int16;
    case IOComponent::UINT:
      return ScalarType::UInt32;
    case IOComponent::INT:
      return ScalarType::Int32;
    case IOComponent::ULONG:
      if (size == 4) return ScalarType::UInt32;
      break;
    case IOComponent::LONG:
      if (size == 4) return ScalarType::Int32;
      break;
    case IOComponent::FLOAT:
      return ScalarType::Float32;
    case IOComponent::DOUBLE:
      return ScalarType::Float64;
    default:
      break;
  }
  throw InputError(what + ": sample type '" + itk::ImageIOBase::GetComponentTypeAsString(c) +
                   "' is not supported (int8 to uint32, float or double)");
}

IOComponent component_of(ScalarType t) {
  switch (t) {
    case ScalarType::Int8:
      return IOComponent::CHAR;
    case ScalarType::UInt8:
      return IOComponent::UCHAR;
    case ScalarType::Int16:
      return IOComponent::SHORT;
    case ScalarType::UInt16:
      return IOComponent::USHORT;
    case ScalarType::Int32:
      return IOComponent::INT;
    case ScalarType::UInt32:
      return IOComponent::UINT;
    case ScalarType::Float32:
      return IOComponent::FLOAT;
    case ScalarType::Float64:
      return IOComponent::DOUBLE;
  }
  return IOComponent::UCHAR;
}

// ITK's warnings (e.g. "Analyze file is deprecated", "No Series were found") and GDCM's
// warnings and errors (e.g. "position is not unique", several lines each) would reach the user's
// terminal beside the one error line; what matters comes back as exceptions or is checked here.
void quiet_itk() {
  itk::Object::GlobalWarningDisplayOff();
  gdcm::Trace::WarningOff();
  gdcm::Trace::ErrorOff();
}

itk::ImageIOBase::Pointer make_io(ItkInput::Kind kind) {
  quiet_itk();
  switch (kind) {
    case ItkInput::Kind::Nifti:
      return itk::NiftiImageIO::New().GetPointer();
    case ItkInput::Kind::MetaImage:
      return itk::MetaImageIO::New().GetPointer();
    case ItkInput::Kind::Tiff:
    case ItkInput::Kind::TiffStack:
      quiet_libtiff();
      return itk::TIFFImageIO::New().GetPointer();
    case ItkInput::Kind::Dicom:
      return itk::GDCMImageIO::New().GetPointer();
  }
  return nullptr;
}

const char* format_name(ItkInput::Kind kind) {
  switch (kind) {
    case ItkInput::Kind::Nifti:
      return "NIfTI";
    case ItkInput::Kind::MetaImage:
      return "MetaImage";
    case ItkInput::Kind::Tiff:
    case ItkInput::Kind::TiffStack:
      return "TIFF";
    case ItkInput::Kind::Dicom:
      return "DICOM";
  }
  return "?";
}

// One file's header as ITK sees it, reduced to at most 3 axes (trailing axes of size 1 dropped).
struct FileHeader {
  ScalarType type = ScalarType::UInt8;
  std::string type_name;  // ITK's, e.g. "unsigned_short"
  unsigned axes = 0;
  Index3 dims{1, 1, 1};
  Vec3d spacing{1, 1, 1};
  Vec3d origin{0, 0, 0};
  Mat3 direction = kIdentity3;
};

FileHeader read_header(itk::ImageIOBase& io, const std::string& file) {
  // MetaIO's CanRead wants the extension in lower case; isotile's own header check has already
  // judged a MetaImage file (.MHA included).
  if (!dynamic_cast<itk::MetaImageIO*>(&io) && !io.CanReadFile(file.c_str())) {
    std::string name = io.GetNameOfClass();  // e.g. TIFFImageIO
    if (name.ends_with("ImageIO")) name.resize(name.size() - 7);
    throw InputError(file + ": not a readable " + name + " file");
  }
  io.SetFileName(file);
  try {
    io.ReadImageInformation();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(file + ": " + itk_message(e));
  }
  if (io.GetNumberOfComponents() != 1)
    throw InputError(file + ": " + std::to_string(io.GetNumberOfComponents()) +
                     " components per sample (e.g. colour); a volume needs one");
  FileHeader h;
  h.type = scalar_of(io.GetComponentType(), io.GetComponentSize(), file);
  h.type_name = itk::ImageIOBase::GetComponentTypeAsString(io.GetComponentType());
  unsigned n = io.GetNumberOfDimensions();
  while (n > 3 && io.GetDimensions(n - 1) == 1) --n;
  if (n > 3 || n == 0)
    throw InputError(file + ": " + std::to_string(n) + " axes; a volume needs 3");
  h.axes = n;
  for (unsigned a = 0; a < n; ++a) {
    h.dims[a] = static_cast<std::int64_t>(io.GetDimensions(a));
    h.spacing[a] = io.GetSpacing(a);
    h.origin[a] = io.GetOrigin(a);
    const std::vector<double> d = io.GetDirection(a);
    for (unsigned r = 0; r < 3 && r < d.size(); ++r) h.direction[3 * r + a] = d[r];
  }
  if (n == 2) {
    // A slice: its normal completes a right-handed frame.
    const Mat3& m = h.direction;
    h.direction[2] = m[3] * m[7] - m[6] * m[4];
    h.direction[5] = m[6] * m[1] - m[0] * m[7];
    h.direction[8] = m[0] * m[4] - m[3] * m[1];
  }
  for (int a = 0; a < 3; ++a) {
    if (h.dims[a] <= 0) throw InputError(file + ": an axis of size 0");
    // A multi-frame DICOM file's step between frames is judged once the frames are placed
    // (place_frames): GDCM's is negative where they descend along the normal.
    const bool placed_later = a == 2 && h.dims[2] > 1 && dynamic_cast<itk::GDCMImageIO*>(&io);
    if ((!std::isfinite(h.spacing[a]) || h.spacing[a] <= 0) && !placed_later)
      throw InputError(file + ": spacing " + std::to_string(h.spacing[a]) + " along axis " +
                       std::to_string(a) + " (must be positive)");
    if (!std::isfinite(h.origin[a])) throw InputError(file + ": the origin is not finite");
  }
  for (double c : h.direction)
    if (!std::isfinite(c)) throw InputError(file + ": the direction cosines are not finite");
  return h;
}

void read_samples(itk::ImageIOBase& io, const std::string& file, const FileHeader& h, void* out) {
  itk::ImageIORegion region(h.axes);
  for (unsigned a = 0; a < h.axes; ++a) {
    region.SetIndex(a, 0);
    region.SetSize(a, static_cast<itk::SizeValueType>(h.dims[a]));
  }
  io.SetIORegion(region);
  try {
    io.Read(out);
  } catch (const itk::ExceptionObject& e) {
    throw InputError(file + ": " + itk_message(e));
  }
}

std::string series_tag(itk::GDCMImageIO& io, const char* key) {
  std::string value;
  itk::ExposeMetaData<std::string>(io.GetMetaDataDictionary(), key, value);
  while (!value.empty() && (value.back() == ' ' || value.back() == '\0')) value.pop_back();
  return value;
}

// GDCM's scan of a folder stumbles on an entry that is not a file it can open (a dangling link,
// a FIFO: opening one waits for a writer): its sorting then gives up, and the slices come back
// in another order, which the gap check below reported as missing slices. Such an entry is named
// instead. Subfolders are not scanned (SetRecursive(false)).
void check_series_folder(const std::string& dir) {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    std::error_code status_ec;
    const std::filesystem::file_status st = std::filesystem::status(entry.path(), status_ec);
    if (st.type() == std::filesystem::file_type::not_found)
      throw InputError(entry.path().string() +
                       ": a link to nothing in the DICOM folder; remove it (a folder's files "
                       "are read as one series)");
    if (std::filesystem::is_directory(st) || std::filesystem::is_regular_file(st)) continue;
    if (status_ec)
      throw InputError(entry.path().string() + ": cannot be examined in the DICOM folder (" +
                       status_ec.message() +
                       "); remove it (a folder's files are read as one series)");
    throw InputError(entry.path().string() +
                     ": not a regular file (a FIFO, socket or device) in the DICOM folder; "
                     "remove it (a folder's files are read as one series)");
  }
}

itk::GDCMSeriesFileNames::Pointer scan_series(const std::string& dir) {
  quiet_itk();
  check_series_folder(dir);
  auto names = itk::GDCMSeriesFileNames::New();
  names->SetUseSeriesDetails(false);
  names->SetRecursive(false);
  try {
    names->SetDirectory(dir);
  } catch (const itk::ExceptionObject& e) {
    throw InputError(dir + ": " + itk_message(e));
  }
  return names;
}

// ImageOrientationPatient must be two unit vectors at right angles: a slice's normal (row x
// column) orders a series, and slices whose column leans off the row were refused as lying "at
// the same position".
void check_orientation(const std::string& file, const std::array<double, 6>& o) {
  const Vec3d row{o[0], o[1], o[2]}, column{o[3], o[4], o[5]};
  if (std::abs(dot(row, row) - 1) > 1e-3 || std::abs(dot(column, column) - 1) > 1e-3 ||
      std::abs(dot(row, column)) > 1e-3)
    throw InputError(file +
                     ": ImageOrientationPatient (0020,0037) is not two unit vectors at "
                     "right angles (row and column lengths " +
                     short_number(std::sqrt(dot(row, row))) + " and " +
                     short_number(std::sqrt(dot(column, column))) + ", cosine between them " +
                     short_number(dot(row, column)) + ")");
}

// A multi-frame DICOM file's frames placed by their own positions (an enhanced file's functional
// groups, RT Dose's offsets), checked as a series' slices are; GDCM's geometry is kept for files
// that give one position and a spacing. Returns what it read.
DicomFrames place_frames(const ItkInput& input, const std::string& file, ItkImageInfo& info) {
  DicomFrames frames = read_dicom_frames(file, info.dims[2]);
  if (frames.orientation) {
    const std::array<double, 6>& o = *frames.orientation;
    check_orientation(file, o);
    const Vec3d row{o[0], o[1], o[2]}, column{o[3], o[4], o[5]};
    const Vec3d normal = cross(row, column);
    const double length = std::sqrt(dot(normal, normal));
    for (int r = 0; r < 3; ++r) {
      info.direction[3 * r] = row[r];
      info.direction[3 * r + 1] = column[r];
      info.direction[3 * r + 2] = normal[r] / length;
    }
  }
  if (frames.pixel_spacing) {
    // PixelSpacing is the distance between rows (along y), then between columns (along x).
    info.spacing[0] = (*frames.pixel_spacing)[1];
    info.spacing[1] = (*frames.pixel_spacing)[0];
  }
  if (frames.positions.empty()) {
    // GDCM then places the frames 1 mm apart from 0, 0, 0.
    if (frames.functional_groups)
      throw InputError(file +
                       ": its frames have no ImagePositionPatient (PlanePositionSequence), so "
                       "they cannot be placed");
    // GDCM stacks any frames as slices, 1 mm apart where it finds no distance: a cine loop
    // would be meshed as a volume. --spacing says the frames are slices and how far apart.
    const std::string count = std::to_string(info.dims[2]);
    if (!frames.frames_over.empty() && !input.spacing_given)
      throw InputError(file + ": its " + count + " frames run over " + frames.frames_over +
                       " (its FrameIncrementPointer), not over slice positions: a series in "
                       "time or of projections, not a volume; --spacing X,Y,Z stacks them as "
                       "slices that far apart");
    if (!frames.frame_spacing_unknown.empty() && !input.spacing_given)
      throw InputError(file + ": its " + count + " frames carry no positions and " +
                       frames.frame_spacing_unknown +
                       ", so the distance between them is unknown; give the spacing with "
                       "--spacing X,Y,Z");
    if (!std::isfinite(info.spacing[2]) || info.spacing[2] <= 0)
      throw InputError(file + ": spacing " + std::to_string(info.spacing[2]) +
                       " between frames (must be positive)");
    return frames;
  }
  const SliceStack stack = stack_along_normal(
      input.path, frames.positions, {info.direction[2], info.direction[5], info.direction[8]},
      {"frame", "frames"}, [](std::size_t k) { return std::to_string(k + 1); });
  info.spacing[2] = stack.step;
  info.origin = frames.positions[stack.order[0]];
  if (!std::is_sorted(stack.order.begin(), stack.order.end())) info.frame_order = stack.order;
  return frames;
}

// A stack of 2D files (DICOM slices, TIFF pages), ordered in z.
ItkImageInfo stack_info(const ItkInput& input, std::vector<std::string> files) {
  const bool dicom = input.kind == ItkInput::Kind::Dicom;
  auto io = make_io(input.kind);
  std::vector<FileHeader> h;
  h.reserve(files.size());
  ItkImageInfo info;
  std::vector<std::string> spacing_text;  // each DICOM slice's PixelSpacing, as its file says
  for (std::size_t k = 0; k < files.size(); ++k) {
    h.push_back(read_header(*io, files[k]));
    if (!dicom || files.size() == 1) continue;
    auto& gdcm = static_cast<itk::GDCMImageIO&>(*io);
    // GDCM puts a slice without a position at 0, 0, 0: reported as a gap or a tilt. An enhanced
    // file of one frame gives its position in its functional group.
    if (h.back().dims[2] == 1 && series_tag(gdcm, "0020|0032").empty() &&
        read_dicom_frames(files[k], 1).positions.empty())
      throw InputError(files[k] +
                       ": no ImagePositionPatient (0020,0032); the slices of a series cannot be "
                       "placed without it");
    // Likewise the orientation, whose normal orders the slices: GDCM's default put every slice
    // of a sagittal series "at the same position".
    if (h.back().dims[2] == 1) {
      const std::string iop = series_tag(gdcm, "0020|0037");
      std::array<double, 6> o{};
      int got = 0;
      if (!iop.empty()) {
        std::string text = iop;
        std::replace(text.begin(), text.end(), '\\', ' ');
        std::istringstream in(text);
        while (got < 6 && in >> o[got]) ++got;
      }
      if (got == 6) {
        check_orientation(files[k], o);
      } else if (!read_dicom_frames(files[k], 1).orientation) {
        throw InputError(files[k] +
                         (iop.empty() ? ": no ImageOrientationPatient (0020,0037)"
                                      : ": ImageOrientationPatient (0020,0037) '" + iop +
                                            "' is not six numbers") +
                         "; the slices of a series cannot be ordered without it");
      }
    }
    // What read_dicom_frames checks in the first file, in every slice: ITK reads each by itself,
    // so one MONOCHROME1 slice among MONOCHROME2 ones came out inverted, exit 0.
    check_photometric(files[k], series_tag(gdcm, "0028|0004"));
    spacing_text.push_back(series_tag(gdcm, "0028|0030"));
    // Each slice's rescale, as GDCM applies it to that slice.
    const double slope = gdcm.GetRescaleSlope(), intercept = gdcm.GetRescaleIntercept();
    RescaleRange& r = info.rescale_range;
    r.slope_min = k ? std::min(r.slope_min, slope) : slope;
    r.slope_max = k ? std::max(r.slope_max, slope) : slope;
    r.intercept_min = k ? std::min(r.intercept_min, intercept) : intercept;
    r.intercept_max = k ? std::max(r.intercept_max, intercept) : intercept;
  }
  DicomFrames geometry;  // the first file's, as DICOM files give it
  info.format = format_name(input.kind);
  if (files.size() == 1) {
    // One file holding the whole volume (multi-frame DICOM, multi-page TIFF).
    if (h[0].axes < 3 || h[0].dims[2] < 2)
      throw InputError(input.path + ": one " + info.format +
                       " slice; a volume needs several (give the directory or the series)");
    info.type = h[0].type;
    info.dims = h[0].dims;
    info.spacing = h[0].spacing;
    info.origin = h[0].origin;
    info.direction = h[0].direction;
    if (dicom) geometry = place_frames(input, files[0], info);
  } else {
    const FileHeader first = h[0];
    for (std::size_t k = 0; k < files.size(); ++k) {
      if (h[k].dims[2] != 1 && dicom)
        throw InputError(input.path + ": a multi-frame file in a series of several files (" +
                         files[k] + " holds " + std::to_string(h[k].dims[2]) +
                         " frames); isotile reads such a file by itself: name it");
      if (h[k].dims[2] != 1 || h[k].dims[0] != first.dims[0] || h[k].dims[1] != first.dims[1])
        throw InputError(files[k] + ": slice of " + std::to_string(h[k].dims[0]) + "x" +
                         std::to_string(h[k].dims[1]) + "x" + std::to_string(h[k].dims[2]) +
                         " where " + files[0] + " has " + std::to_string(first.dims[0]) + "x" +
                         std::to_string(first.dims[1]) + "x1");
      if (h[k].type != first.type)
        throw InputError(files[k] + ": samples of type " + h[k].type_name + " where " + files[0] +
                         " holds " + first.type_name +
                         (dicom ? " (different rescale slopes or pixel formats in one series)"
                                : " (slices of one stack must hold one sample type)"));
    }
    info.type = first.type;
    info.dims = {first.dims[0], first.dims[1], static_cast<std::int64_t>(files.size())};
    info.spacing = first.spacing;
    info.direction = first.direction;
    info.origin = first.origin;
    if (dicom) {
      // Where GDCM reads PixelSpacing for this kind of image (CT, MR...), a 0 in a later slice
      // was read as 1 mm: named as the first slice's is, not as a spacing that differs (or as
      // none where the first slice's is 1 mm).
      geometry = read_dicom_frames(files[0], 1);
      const std::string& element = geometry.spacing_element;
      if (element.rfind("PixelSpacing ", 0) == 0)
        for (std::size_t k = 1; k < files.size(); ++k)
          if (!spacing_text[k].empty()) check_pixel_spacing(files[k], element, spacing_text[k]);
      for (std::size_t k = 0; k < files.size(); ++k)
        for (int c = 0; c < 3; ++c)
          if (std::abs(h[k].direction[3 * c] - first.direction[3 * c]) > 1e-4 ||
              std::abs(h[k].direction[3 * c + 1] - first.direction[3 * c + 1]) > 1e-4)
            throw InputError(files[k] + ": slice orientation differs from " + files[0] + "'s");
      // GDCM stacks the slices at the first one's pixel spacing, as it does a multi-frame file's
      // frames (dicom_frames.cpp refuses those): half a series at another scale came out at the
      // first's, exit 0.
      for (std::size_t k = 0; k < files.size(); ++k)
        if (std::abs(h[k].spacing[0] - first.spacing[0]) > 1e-6 * first.spacing[0] ||
            std::abs(h[k].spacing[1] - first.spacing[1]) > 1e-6 * first.spacing[1])
          throw InputError(files[k] + ": pixel spacing " + short_number(h[k].spacing[1]) + " x " +
                           short_number(h[k].spacing[0]) + " where " + files[0] + "'s is " +
                           short_number(first.spacing[1]) + " x " + short_number(first.spacing[0]) +
                           " (PixelSpacing, rows then columns); one volume needs it alike in "
                           "every slice");
      std::vector<Vec3d> origins(files.size());
      for (std::size_t k = 0; k < files.size(); ++k) origins[k] = h[k].origin;
      const SliceStack stack = stack_along_normal(
          input.path, origins, {first.direction[2], first.direction[5], first.direction[8]},
          {"slice", "slices"},
          [&](std::size_t k) { return fs::path(files[k]).filename().string(); });
      std::vector<std::string> sorted(files.size());
      for (std::size_t k = 0; k < files.size(); ++k) sorted[k] = files[stack.order[k]];
      files = std::move(sorted);
      info.origin = h[stack.order[0]].origin;
      info.spacing[2] = stack.step;
    }
  }
  info.files = std::move(files);
  if (dicom) {
    auto& gdcm = static_cast<itk::GDCMImageIO&>(*io);
    read_header(gdcm, info.files.front());
    info.rescale_slope = gdcm.GetRescaleSlope();
    info.rescale_intercept = gdcm.GetRescaleIntercept();
    info.rescaled = info.rescale_slope != 1 || info.rescale_intercept != 0;
    info.series_description = series_tag(gdcm, "0008|103e");
    // Without the pixel spacing GDCM reads for this kind of image (PixelSpacing for CT and MR,
    // ImagerPixelSpacing for projections...), it takes 1 mm and says so only in a warning: a
    // mesh of made-up size.
    if (!geometry.spacing_known && !input.spacing_given) {
      char step[64] = "";
      if (info.files.size() > 1)
        std::snprintf(step, sizeof step, " (the slices lie %g mm apart)", info.spacing[2]);
      throw InputError(info.files.front() + ": no " + geometry.spacing_element +
                       ", the element GDCM reads this kind of image's pixel spacing from, so the "
                       "distance between its pixels is unknown; give the spacing with --spacing "
                       "X,Y,Z" +
                       std::string(step));
    }
  }
  return info;
}

// Names in the order a person numbers them: runs of digits compare as numbers (img_2 before
// img_10, as acquisition software that does not pad its numbers means them), the rest as text;
// names equal so (img_01, img_1) fall back to plain text order.
bool natural_less(const std::string& a, const std::string& b) {
  const auto digit = [](char c) { return c >= '0' && c <= '9'; };
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (digit(a[i]) && digit(b[j])) {
      std::size_t ei = i, ej = j;
      while (ei < a.size() && digit(a[ei])) ++ei;
      while (ej < b.size() && digit(b[ej])) ++ej;
      std::size_t si = i, sj = j;  // leading zeros do not count
      while (si + 1 < ei && a[si] == '0') ++si;
      while (sj + 1 < ej && b[sj] == '0') ++sj;
      if (ei - si != ej - sj) return ei - si < ej - sj;
      const int c = a.compare(si, ei - si, b, sj, ej - sj);
      if (c != 0) return c < 0;
      i = ei;
      j = ej;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i;
      ++j;
    }
  }
  if ((i < a.size()) != (j < b.size())) return j < b.size();
  return a < b;
}

std::vector<std::string> sorted_files(const fs::path& dir, bool (*keep)(const fs::path&)) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_regular_file() && keep(e.path())) out.push_back(e.path().string());
  if (ec) throw IoError("cannot list " + dir.string() + ": " + ec.message());
  std::sort(out.begin(), out.end(), natural_less);
  return out;
}

bool tiff_name(const fs::path& p) {
  const std::string ext = lower_extension(p);
  return ext == ".tif" || ext == ".tiff";
}

// A directory of slices numbered alike (one prefix and suffix round the last run of digits) must
// hold every number from its first to its last, and no file outside that numbering: a missing
// slice moved every one above it down a spacing, and a stray notes.tif became a slice, exit 0 (a
// pattern's stack refused the same gap). Names that share no numbering are taken as they sort.
void check_slice_numbers(const std::string& dir, const std::vector<std::string>& files) {
  struct Numbered {
    std::string prefix, suffix;
    std::int64_t number = -1;
  };
  const auto numbered = [](const std::string& file) {
    const std::string name = fs::path(file).filename().string();
    Numbered n;
    const std::size_t end = name.find_last_of("0123456789");
    if (end == std::string::npos) return n;
    std::size_t begin = end;
    while (begin > 0 && name[begin - 1] >= '0' && name[begin - 1] <= '9') --begin;
    if (end - begin >= 18) return n;
    n.prefix = name.substr(0, begin);
    n.suffix = name.substr(end + 1);
    n.number = std::stoll(name.substr(begin, end + 1 - begin));
    return n;
  };
  std::vector<Numbered> names;
  for (const std::string& f : files) names.push_back(numbered(f));
  // The numbering most of the files share.
  std::map<std::pair<std::string, std::string>, std::size_t> counts;
  for (const Numbered& n : names)
    if (n.number >= 0) ++counts[{n.prefix, n.suffix}];
  if (counts.empty()) return;
  const auto common = std::max_element(counts.begin(), counts.end(),
                                       [](auto& a, auto& b) { return a.second < b.second; });
  if (common->second < 2 || 2 * common->second <= files.size()) return;
  const auto& [prefix, suffix] = common->first;
  std::map<std::int64_t, std::string> numbers;  // number -> file name
  for (std::size_t k = 0; k < files.size(); ++k) {
    if (names[k].number < 0 || names[k].prefix != prefix || names[k].suffix != suffix)
      throw InputError(dir + ": " + fs::path(files[k]).filename().string() +
                       " is not numbered as its other " + std::to_string(common->second) +
                       " slices are (" + prefix + "N" + suffix +
                       "); a stack holds its slices only: move it out");
    const std::string name = fs::path(files[k]).filename().string();
    if (const auto [at, added] = numbers.emplace(names[k].number, name); !added)
      throw InputError(dir + ": " + at->second + " and " + name + " are both slice " +
                       std::to_string(names[k].number) + "; a stack has one of each");
  }
  for (auto at = numbers.begin(); std::next(at) != numbers.end(); ++at)
    if (std::next(at)->first != at->first + 1)
      throw InputError(dir + ": slice number " + std::to_string(at->first + 1) +
                       " is missing, between " + at->second + " and " + std::next(at)->second +
                       "; a stack needs every slice");
}

std::vector<std::string> stack_files(const ItkInput& input) {
  if (input.kind == ItkInput::Kind::TiffStack) {
    if (fs::is_directory(input.path)) {
      auto files = sorted_files(input.path, tiff_name);
      if (files.empty()) throw InputError(input.path + ": no .tif files in the directory");
      check_slice_numbers(input.path, files);
      return files;
    }
    return numbered_files(input.path);
  }
  // DICOM: the directory, or the directory of the file given; a multi-frame file given is a
  // volume of its own (several may share a series: stacks, echoes, time points).
  const bool dir = fs::is_directory(input.path);
  if (!dir && input.series.empty()) {
    auto io = make_io(input.kind);
    const FileHeader h = read_header(*io, input.path);
    if (h.axes == 3 && h.dims[2] > 1) return {input.path};
  }
  const std::string where = dir ? input.path : fs::path(input.path).parent_path().string();
  auto names = scan_series(where.empty() ? "." : where);
  const std::vector<std::string> uids = names->GetSeriesUIDs();
  if (uids.empty()) throw InputError(input.path + ": no DICOM series found");
  std::string uid = input.series;
  if (!uid.empty()) {
    if (std::find(uids.begin(), uids.end(), uid) == uids.end())
      throw InputError(input.path + ": no DICOM series with UID " + uid + " (there are " +
                       std::to_string(uids.size()) + "; `isotile info` lists them)");
  } else if (!dir) {
    // The series of the file given.
    const fs::path self = fs::weakly_canonical(input.path);
    for (const std::string& u : uids)
      for (const std::string& f : names->GetFileNames(u))
        if (fs::weakly_canonical(f) == self) uid = u;
    if (uid.empty()) throw InputError(input.path + ": not part of a DICOM series GDCM can read");
  } else if (uids.size() > 1) {
    std::string list;
    for (const std::string& u : uids) list += (list.empty() ? "" : ", ") + u;
    throw InputError(
        input.path + ": " + std::to_string(uids.size()) +
        " DICOM series; choose one with --series UID (`isotile info` lists them): " + list);
  } else {
    uid = uids.front();
  }
  return names->GetFileNames(uid);
}

}  // namespace

bool itk_available() {
  return true;
}

bool is_dicom_file(const std::string& path) {
  auto io = itk::GDCMImageIO::New();
  return io->CanReadFile(path.c_str());
}

std::vector<DicomSeriesInfo> list_dicom_series(const std::string& directory) {
  auto names = scan_series(directory);
  std::vector<DicomSeriesInfo> out;
  auto io = itk::GDCMImageIO::New();
  for (const std::string& uid : names->GetSeriesUIDs()) {
    const std::vector<std::string> files = names->GetFileNames(uid);
    DicomSeriesInfo s;
    s.uid = uid;
    s.files = static_cast<std::int64_t>(files.size());
    if (!files.empty()) {
      const FileHeader h = read_header(*io, files.front());
      s.columns = h.dims[0];
      s.rows = h.dims[1];
      s.description = series_tag(*io, "0008|103e");
    }
    out.push_back(s);
  }
  return out;
}

ItkImageInfo read_itk_info(const ItkInput& input) {
  try {
    if (input.kind == ItkInput::Kind::Dicom || input.kind == ItkInput::Kind::TiffStack) {
      ItkImageInfo info = stack_info(input, stack_files(input));
      if (input.kind == ItkInput::Kind::Dicom) {
        info.series_uid = input.series;
        if (info.series_uid.empty()) {
          auto io = itk::GDCMImageIO::New();
          read_header(*io, info.files.front());
          info.series_uid = series_tag(*io, "0020|000e");
        }
      }
      return info;
    }
    auto io = make_io(input.kind);
    const FileHeader h = read_header(*io, input.path);
    if (h.axes < 3 || h.dims[2] < 2) {
      if (input.kind == ItkInput::Kind::Tiff)
        throw InputError(input.path +
                         ": one TIFF page; a volume needs several (a multi-page file, a directory "
                         "of slices or a pattern such as slice_%03d.tif)");
      throw InputError(input.path + ": a 2D image; a volume needs 3 axes");
    }
    ItkImageInfo info;
    info.format = format_name(input.kind);
    info.type = h.type;
    info.dims = h.dims;
    info.spacing = h.spacing;
    info.origin = h.origin;
    info.direction = h.direction;
    return info;
  } catch (const itk::ExceptionObject& e) {
    throw InputError(input.path + ": " + itk_message(e));
  }
}

void read_itk_data(const ItkInput& input, const ItkImageInfo& info, void* out) {
  try {
    auto io = make_io(input.kind);
    if (info.files.size() <= 1 && input.kind != ItkInput::Kind::Dicom &&
        input.kind != ItkInput::Kind::TiffStack) {
      const FileHeader h = read_header(*io, input.path);
      if (h.dims != info.dims || h.type != info.type)
        throw InputError(input.path + ": the file changed while it was read");
      read_samples(*io, input.path, h, out);
      return;
    }
    const std::size_t plane =
        static_cast<std::size_t>(info.dims[0] * info.dims[1]) * type_size(info.type);
    auto* dst = static_cast<char*>(out);
    for (const std::string& f : info.files) {
      const FileHeader h = read_header(*io, f);
      if (h.type != info.type || h.dims[0] != info.dims[0] || h.dims[1] != info.dims[1])
        throw InputError(f + ": the file changed while it was read");
      read_samples(*io, f, h, dst);
      dst += plane * static_cast<std::size_t>(h.dims[2]);
    }
    if (!info.frame_order.empty()) {
      // A multi-frame file's frames into their order along the normal, cycle by cycle through
      // one plane's room.
      auto* base = static_cast<char*>(out);
      std::vector<char> held(plane);
      std::vector<bool> done(info.frame_order.size());
      for (std::size_t start = 0; start < done.size(); ++start) {
        if (done[start]) continue;
        std::memcpy(held.data(), base + start * plane, plane);
        for (std::size_t k = start;;) {
          done[k] = true;
          const std::size_t from = info.frame_order[k];
          if (from == start) {
            std::memcpy(base + k * plane, held.data(), plane);
            break;
          }
          std::memcpy(base + k * plane, base + from * plane, plane);
          k = from;
        }
      }
    }
  } catch (const itk::ExceptionObject& e) {
    throw InputError(input.path + ": " + itk_message(e));
  }
}

void write_itk(const std::string& path, const void* data, ScalarType type, const Index3& dims,
               const Vec3d& spacing, const Vec3d& origin, const Mat3& direction) {
  const std::string name = fs::path(path).filename().string();
  itk::ImageIOBase::Pointer io;
  if (name.find(".nii") != std::string::npos)
    io = itk::NiftiImageIO::New().GetPointer();
  else if (tiff_name(path)) {
    quiet_libtiff();
    io = itk::TIFFImageIO::New().GetPointer();
  } else
    io = itk::MetaImageIO::New().GetPointer();
  io->SetNumberOfDimensions(3);
  io->SetFileName(path);
  io->SetComponentType(component_of(type));
  io->SetPixelType(itk::IOPixelEnum::SCALAR);
  io->SetNumberOfComponents(1);
  itk::ImageIORegion region(3);
  for (unsigned a = 0; a < 3; ++a) {
    io->SetDimensions(a, static_cast<itk::SizeValueType>(dims[a]));
    io->SetSpacing(a, spacing[a]);
    io->SetOrigin(a, origin[a]);
    io->SetDirection(a, std::vector<double>{direction[a], direction[3 + a], direction[6 + a]});
    region.SetIndex(a, 0);
    region.SetSize(a, static_cast<itk::SizeValueType>(dims[a]));
  }
  io->SetIORegion(region);
  io->SetUseCompression(name.size() > 3 && name.substr(name.size() - 3) == ".gz");
  try {
    io->WriteImageInformation();
    io->Write(data);
  } catch (const itk::ExceptionObject& e) {
    throw IoError("cannot write " + path + ": " + itk_message(e));
  }
}

}  // namespace isotile
