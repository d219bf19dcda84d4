// Per-frame geometry of multi-frame DICOM files, through GDCM's data set (dicom_frames.h).
#include "core/volume/dicom_frames.h"

#include <gdcmAttribute.h>
#include <gdcmDataSet.h>
#include <gdcmDicts.h>
#include <gdcmGlobal.h>
#include <gdcmImageHelper.h>
#include <gdcmMediaStorage.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmUIDs.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <set>

#include "core/errors.h"

namespace isotile {

namespace {

const gdcm::Tag kSharedGroups(0x5200, 0x9229), kPerFrameGroups(0x5200, 0x9230);
const gdcm::Tag kPlanePosition(0x0020, 0x9113), kPlaneOrientation(0x0020, 0x9116);
const gdcm::Tag kPixelMeasures(0x0028, 0x9110), kValueTransformation(0x0028, 0x9145);
const gdcm::Tag kPosition(0x0020, 0x0032), kOrientation(0x0020, 0x0037);
const gdcm::Tag kPixelSpacing(0x0028, 0x0030);
const gdcm::Tag kImagerPixelSpacing(0x0018, 0x1164);
const gdcm::Tag kPhotometric(0x0028, 0x0004);
const gdcm::Tag kIntercept(0x0028, 0x1052), kSlope(0x0028, 0x1053);
const gdcm::Tag kGridFrameOffsets(0x3004, 0x000C);

// GDCM's own choice of the elements that give an image's pixel spacing and the distance between
// its frames (by its SOP class), which GDCM 3.0 declares protected: the same tables, not copies.
struct GdcmSpacingTag : gdcm::ImageHelper {
  using gdcm::ImageHelper::GetSpacingTagFromMediaStorage;
  using gdcm::ImageHelper::GetZSpacingTagFromMediaStorage;
};

std::string tag_text(const gdcm::Tag& t) {
  char text[16];
  std::snprintf(text, sizeof text, "(%04X,%04X)", t.GetGroup(), t.GetElement());
  return text;
}

// "PixelSpacing (0028,0030)": the element's keyword in GDCM's dictionary and its tag.
std::string element_name(const gdcm::Tag& t) {
  const char* keyword = gdcm::Global::GetInstance().GetDicts().GetDictEntry(t).GetKeyword();
  return std::string(keyword && *keyword ? std::string(keyword) + " " : "") + tag_text(t);
}

// A text element's values ("1.5\\-2\\3" -> "1.5", "-2", "3"), without their padding; one empty
// value for empty text.
std::vector<std::string> split_values(const std::string& text) {
  std::vector<std::string> out;
  std::size_t at = 0;
  while (at <= text.size()) {
    std::size_t end = text.find('\\', at);
    if (end == std::string::npos) end = text.size();
    std::string value = text.substr(at, end - at);
    while (!value.empty() && (value.back() == ' ' || value.back() == '\0')) value.pop_back();
    while (!value.empty() && value.front() == ' ') value.erase(value.begin());
    out.push_back(std::move(value));
    at = end + 1;
  }
  return out;
}

// split_values of an element's bytes; none where the element holds no bytes.
std::vector<std::string> text_values(const gdcm::DataElement& e) {
  const gdcm::ByteValue* bytes = e.GetByteValue();
  if (!bytes) return {};
  return split_values(std::string(bytes->GetPointer(), bytes->GetLength()));
}

// What the frames of a multi-frame file without per-frame positions run over, by its
// FrameIncrementPointer (dicom_frames.h): the elements it names, other than the slice vectors,
// whose value changes from frame to frame (FrameTime always: one step in time per frame).
// Empty where the file names none.
std::string frames_over(const gdcm::DataSet& ds) {
  const gdcm::Tag pointer(0x0028, 0x0009);
  if (!ds.FindDataElement(pointer) || ds.GetDataElement(pointer).IsEmpty()) return "";
  gdcm::Attribute<0x0028, 0x0009> named;
  named.SetFromDataElement(ds.GetDataElement(pointer));
  const gdcm::Tag frame_time(0x0018, 0x1063);
  const std::set<gdcm::Tag> slices{gdcm::Tag(0x0054, 0x0080),   // NM's SliceVector
                                   gdcm::Tag(0x0018, 0x2005)};  // SliceLocationVector
  std::string over;
  for (unsigned i = 0; i < named.GetNumberOfValues(); ++i) {
    const gdcm::Tag tag = named.GetValue(i);
    if (slices.count(tag) || (tag != frame_time && !ds.FindDataElement(tag))) continue;
    if (tag != frame_time) {
      // One value per frame: NM's vectors are US, the others text (decimal or labels).
      const gdcm::DataElement& e = ds.GetDataElement(tag);
      gdcm::VR vr = e.GetVR();
      if (vr == gdcm::VR::INVALID || vr == gdcm::VR::UN)
        vr = gdcm::Global::GetInstance().GetDicts().GetDictEntry(tag).GetVR();
      std::set<std::string> values;
      if (vr == gdcm::VR::US) {
        const gdcm::ByteValue* bytes = e.GetByteValue();
        const std::string raw = bytes ? std::string(bytes->GetPointer(), bytes->GetLength()) : "";
        for (std::size_t at = 0; at + 2 <= raw.size(); at += 2) values.insert(raw.substr(at, 2));
      } else {
        for (std::string& v : text_values(e)) values.insert(std::move(v));
      }
      if (values.size() < 2) continue;  // alike in every frame: not what they run over
    }
    over += (over.empty() ? "" : ", ") + element_name(tag);
  }
  return over;
}

// A decimal string's values ("1.5\-2\3"); empty where the element holds none.
std::vector<double> decimals(const gdcm::DataElement& e, const std::string& path) {
  std::vector<double> out;
  for (const std::string& value : text_values(e)) {
    char* stop = nullptr;
    const double v = std::strtod(value.c_str(), &stop);
    if (value.empty() || *stop != '\0' || !std::isfinite(v)) {
      throw InputError(path + ": DICOM element " + tag_text(e.GetTag()) + " holds '" + value +
                       "' where a decimal number belongs");
    }
    out.push_back(v);
  }
  return out;
}

// Element `tag` in the first item of sequence `macro`, in a frame's group or else in the shared
// one (a frame's own value overrides the shared one, as the standard says).
std::optional<std::vector<double>> group_value(const gdcm::DataSet* frame,
                                               const gdcm::DataSet* shared, gdcm::Tag macro,
                                               gdcm::Tag tag, const std::string& path) {
  for (const gdcm::DataSet* group : {frame, shared}) {
    if (!group || !group->FindDataElement(macro)) continue;
    const gdcm::SmartPointer<gdcm::SequenceOfItems> items =
        group->GetDataElement(macro).GetValueAsSQ();
    if (!items || items->GetNumberOfItems() == 0) continue;
    const gdcm::DataSet& item = items->GetItem(1).GetNestedDataSet();
    if (!item.FindDataElement(tag)) continue;
    return decimals(item.GetDataElement(tag), path);
  }
  return std::nullopt;
}

bool close(const std::vector<double>& a, const std::vector<double>& b, double tolerance) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::abs(a[i] - b[i]) > tolerance * std::max(1.0, std::abs(a[i]))) return false;
  return true;
}

}  // namespace

// MONOCHROME1 only says how to display the values (the lowest white); ITK's DICOM reader turns
// such an image into MONOCHROME2 by inverting the stored values, before the rescale, so the
// samples were no longer in the file's units (-1024 HU read as 64511), exit 0.
void check_photometric(const std::string& path, const std::string& photometric) {
  if (photometric == "MONOCHROME1")
    throw InputError(path +
                     ": PhotometricInterpretation MONOCHROME1 (the lowest value shown white): "
                     "ITK's DICOM reader inverts such samples, so they would not be in the "
                     "file's units (CT's Hounsfield units); isotile does not read them");
}

// A pixel spacing of 0 (or less) is no distance: GDCM took 1 mm for it without a word.
void check_pixel_spacing(const std::string& path, const std::string& element,
                         const std::string& values) {
  const std::vector<std::string> split = split_values(values);
  bool positive = true;
  for (const std::string& value : split) {
    char* stop = nullptr;
    const double v = std::strtod(value.c_str(), &stop);
    positive = positive && !value.empty() && *stop == '\0' && std::isfinite(v) && v > 0;
  }
  if (split.size() != 2 || !positive)
    throw InputError(path + ": " + element + " holds '" + values +
                     "'; a pixel spacing is two positive distances (GDCM takes 1 mm for a 0)");
}

DicomFrames read_dicom_frames(const std::string& path, std::int64_t frames) {
  DicomFrames out;
  gdcm::Reader reader;
  reader.SetFileName(path.c_str());
  // The header only: the pixel data is read afterwards, frame by frame, by GDCM through ITK.
  if (!reader.ReadUpToTag(gdcm::Tag(0x7FE0, 0x0010), std::set<gdcm::Tag>()))
    throw InputError(path + ": GDCM cannot read the DICOM header");
  const gdcm::DataSet& ds = reader.GetFile().GetDataSet();
  const auto has = [&](gdcm::Tag tag) {
    return ds.FindDataElement(tag) && !ds.GetDataElement(tag).IsEmpty();
  };
  gdcm::MediaStorage storage;
  storage.SetFromFile(reader.GetFile());
  const gdcm::Tag spacing_tag = GdcmSpacingTag::GetSpacingTagFromMediaStorage(storage);
  out.spacing_known = spacing_tag == gdcm::Tag(0xFFFF, 0xFFFF) || has(spacing_tag);
  out.spacing_element = element_name(spacing_tag);
  if (has(kPhotometric)) {
    const std::vector<std::string> photometric = text_values(ds.GetDataElement(kPhotometric));
    if (!photometric.empty()) check_photometric(path, photometric.front());
  }
  if ((spacing_tag == kPixelSpacing || spacing_tag == kImagerPixelSpacing) && has(spacing_tag)) {
    std::string values;
    for (const std::string& x : text_values(ds.GetDataElement(spacing_tag)))
      values += (values.empty() ? "" : "\\") + x;
    check_pixel_spacing(path, out.spacing_element, values);
  }
  if (!ds.FindDataElement(kPerFrameGroups)) {
    if (frames < 2) return out;
    if (!has(kGridFrameOffsets) || !has(kPosition) || !has(kOrientation)) {
      // One position for all frames (or none): GDCM's geometry, where the frames are slices
      // and GDCM finds the distance between them.
      out.frames_over = frames_over(ds);
      const gdcm::Tag z = GdcmSpacingTag::GetZSpacingTagFromMediaStorage(storage);
      if (z != gdcm::Tag(0xFFFF, 0xFFFF)) {
        if (!has(z)) out.frame_spacing_unknown = "no " + element_name(z);
      } else {
        gdcm::UIDs kind;
        const bool named = storage.GetString() && kind.SetFromUID(storage.GetString());
        out.frame_spacing_unknown = std::string("GDCM reads no distance between the frames of ") +
                                    (named ? kind.GetName() : "this kind of") + " files";
      }
      return out;
    }
    // RT Dose: the frames' offsets along the normal from the one position (relative to it where
    // the first is 0, else coordinates along the normal; the differences are the same).
    const std::vector<double> offsets = decimals(ds.GetDataElement(kGridFrameOffsets), path);
    const std::vector<double> p = decimals(ds.GetDataElement(kPosition), path),
                              o = decimals(ds.GetDataElement(kOrientation), path);
    if (offsets.size() != static_cast<std::size_t>(frames) || p.size() != 3 || o.size() != 6)
      throw InputError(path + ": DICOM GridFrameOffsetVector holds " +
                       std::to_string(offsets.size()) + " offsets for " + std::to_string(frames) +
                       " frames (or ImagePositionPatient and ImageOrientationPatient are not 3 "
                       "and 6 values)");
    const Vec3d normal = cross({o[0], o[1], o[2]}, {o[3], o[4], o[5]});
    const double length = std::sqrt(dot(normal, normal));
    if (!(length > 0)) throw InputError(path + ": ImageOrientationPatient has no normal");
    for (const double offset : offsets) {
      const double along = (offset - offsets[0]) / length;
      out.positions.push_back(
          {p[0] + along * normal[0], p[1] + along * normal[1], p[2] + along * normal[2]});
    }
    return out;
  }
  out.functional_groups = true;
  gdcm::SmartPointer<gdcm::SequenceOfItems> shared_items;
  const gdcm::DataSet* shared = nullptr;
  if (ds.FindDataElement(kSharedGroups)) {
    shared_items = ds.GetDataElement(kSharedGroups).GetValueAsSQ();
    if (shared_items && shared_items->GetNumberOfItems() > 0)
      shared = &shared_items->GetItem(1).GetNestedDataSet();
  }
  const gdcm::SmartPointer<gdcm::SequenceOfItems> per_frame =
      ds.GetDataElement(kPerFrameGroups).GetValueAsSQ();
  const std::int64_t groups =
      per_frame ? static_cast<std::int64_t>(per_frame->GetNumberOfItems()) : 0;
  if (groups != frames)
    throw InputError(path + ": DICOM file of " + std::to_string(frames) + " frames with " +
                     std::to_string(groups) +
                     " per-frame functional groups (PerFrameFunctionalGroupsSequence); one per "
                     "frame places them");
  std::optional<std::vector<double>> orientation0, spacing0, slope0, intercept0;
  for (std::int64_t f = 0; f < frames; ++f) {
    const gdcm::DataSet& frame =
        per_frame->GetItem(static_cast<std::size_t>(f) + 1).GetNestedDataSet();
    const std::string which = "frame " + std::to_string(f + 1);
    const auto value = [&](gdcm::Tag macro, gdcm::Tag tag) {
      return group_value(&frame, shared, macro, tag, path);
    };
    const std::optional<std::vector<double>> position = value(kPlanePosition, kPosition);
    if (position && position->size() != 3)
      throw InputError(path + ": " + which + "'s ImagePositionPatient holds " +
                       std::to_string(position->size()) + " values (3)");
    if (f > 0 && position.has_value() != !out.positions.empty())
      throw InputError(path + ": " + which + (position ? " has an" : " has no") +
                       " ImagePositionPatient (PlanePositionSequence) where frame 1 " +
                       (position ? "has none" : "has one") + "; the frames cannot be placed");
    if (position) out.positions.push_back({(*position)[0], (*position)[1], (*position)[2]});
    // What one volume needs alike in every frame: GDCM takes the first frame's for all.
    const auto alike = [&](std::optional<std::vector<double>>& first, gdcm::Tag macro,
                           gdcm::Tag tag, const char* what, double tolerance) {
      const std::optional<std::vector<double>> v = value(macro, tag);
      if (f == 0)
        first = v;
      else if (v.has_value() != first.has_value() || (v && !close(*v, *first, tolerance)))
        throw InputError(path + ": " + which + "'s " + what +
                         " differs from frame 1's; one volume needs it alike in every frame");
    };
    alike(orientation0, kPlaneOrientation, kOrientation, "ImageOrientationPatient", 1e-4);
    alike(spacing0, kPixelMeasures, kPixelSpacing, "PixelSpacing", 1e-6);
    alike(slope0, kValueTransformation, kSlope, "RescaleSlope", 1e-9);
    alike(intercept0, kValueTransformation, kIntercept, "RescaleIntercept", 1e-9);
  }
  if (orientation0) {
    if (orientation0->size() != 6)
      throw InputError(path + ": ImageOrientationPatient holds " +
                       std::to_string(orientation0->size()) + " values (6)");
    out.orientation.emplace();
    for (int i = 0; i < 6; ++i) (*out.orientation)[i] = (*orientation0)[i];
  }
  if (spacing0) {
    if (spacing0->size() != 2 || (*spacing0)[0] <= 0 || (*spacing0)[1] <= 0)
      throw InputError(path + ": PixelSpacing must hold two positive values");
    out.pixel_spacing = std::array<double, 2>{(*spacing0)[0], (*spacing0)[1]};
    out.spacing_known = true;
  }
  return out;
}

}  // namespace isotile
