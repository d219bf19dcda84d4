// DICOM Part 10 files walked element by element before GDCM reads them (image_headers.h).
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "core/errors.h"
#include "core/file_names.h"
#include "core/volume/file_bytes.h"
#include "core/volume/image_headers.h"

namespace isotile {

namespace {

namespace fs = std::filesystem;
using file_check::FileBytes;
using file_check::get;

std::string hex_tag(std::uint16_t group, std::uint16_t element) {
  char b[16];
  std::snprintf(b, sizeof b, "(%04X,%04X)", group, element);
  return b;
}

// The VR of the elements GDCM and ITK read through typed attributes (image geometry, pixel
// description, identification); nullptr for the others.
const char* expected_vr(std::uint16_t group, std::uint16_t element) {
  struct Known {
    std::uint16_t group, element;
    const char* vr;
  };
  static constexpr Known kKnown[] = {
      {0x0002, 0x0000, "UL"}, {0x0002, 0x0001, "OB"}, {0x0002, 0x0002, "UI"},
      {0x0002, 0x0003, "UI"}, {0x0002, 0x0010, "UI"}, {0x0002, 0x0012, "UI"},
      {0x0008, 0x0016, "UI"}, {0x0008, 0x0018, "UI"}, {0x0008, 0x0060, "CS"},
      {0x0018, 0x0050, "DS"}, {0x0018, 0x0088, "DS"}, {0x0020, 0x000D, "UI"},
      {0x0020, 0x000E, "UI"}, {0x0020, 0x0011, "IS"}, {0x0020, 0x0012, "IS"},
      {0x0020, 0x0013, "IS"}, {0x0020, 0x0032, "DS"}, {0x0020, 0x0037, "DS"},
      {0x0020, 0x1041, "DS"}, {0x0028, 0x0002, "US"}, {0x0028, 0x0004, "CS"},
      {0x0028, 0x0006, "US"}, {0x0028, 0x0008, "IS"}, {0x0028, 0x0010, "US"},
      {0x0028, 0x0011, "US"}, {0x0028, 0x0030, "DS"}, {0x0028, 0x0100, "US"},
      {0x0028, 0x0101, "US"}, {0x0028, 0x0102, "US"}, {0x0028, 0x0103, "US"},
      {0x0028, 0x1050, "DS"}, {0x0028, 0x1051, "DS"}, {0x0028, 0x1052, "DS"},
      {0x0028, 0x1053, "DS"}, {0x0028, 0x1054, "LO"}, {0x7FE0, 0x0010, "OB"}};
  for (const Known& k : kKnown)
    if (k.group == group && k.element == element) return k.vr;
  return nullptr;
}

// One of the standard's value representations.
bool known_vr(const char* vr) {
  static const char kVrs[] = "AEASATCSDADSDTFLFDISLOLTOBODOFOLOVOWPNSHSLSQSSSTSVTMUCUIULUNURUSUTUV";
  for (std::size_t i = 0; i + 1 < sizeof kVrs; i += 2)
    if (kVrs[i] == vr[0] && kVrs[i + 1] == vr[1]) return true;
  return false;
}

struct DicomWalk {
  DicomWalk(FileBytes& f, const std::string& p) : file(f), path(p) {}
  FileBytes& file;
  const std::string& path;
  bool implicit = false, big = false;
  std::int64_t rows = -1, columns = -1, bits = -1, samples = 1, frames = 1;
  std::int64_t bits_stored = -1, high_bit = -1;
  bool pixel_found = false;
  std::uint64_t pixel_at = 0, pixel_length = 0;
  bool encapsulated = false;

  [[noreturn]] void cut(const std::string& what, std::uint64_t at, std::uint64_t need) const {
    throw InputError(path + ": DICOM " + what + " needs " + std::to_string(need) +
                     " bytes from offset " + std::to_string(at) + " but the file holds " +
                     std::to_string(file.size() > at ? file.size() - at : 0) +
                     " there (truncated file)");
  }
  std::uint16_t u16(const unsigned char* p) const { return get<std::uint16_t>(p, big); }
  std::uint32_t u32(const unsigned char* p) const { return get<std::uint32_t>(p, big); }

  // Elements from `at` until `end` (a defined length), or until the item delimiter when
  // `until_delimiter`. Returns the offset after the last element.
  std::uint64_t dataset(std::uint64_t at, std::uint64_t end, bool until_delimiter, int depth,
                        bool meta) {
    if (depth > 32) throw InputError(path + ": DICOM sequences nested more than 32 deep");
    while (until_delimiter || at < end) {
      unsigned char h[12];
      if (!file.read(at, h, 8)) {
        if (!until_delimiter && at >= file.size() && depth == 0) return at;
        cut("element header", at, 8);
      }
      const std::uint16_t group = u16(h), element = u16(h + 2);
      if (meta && group != 0x0002) return at;
      if (group == 0xFFFE) {
        if (element == 0xE00D && until_delimiter) return at + 8;
        throw InputError(path + ": malformed DICOM: delimiter " + hex_tag(group, element) +
                         " at offset " + std::to_string(at));
      }
      std::uint64_t length = 0, header = 8;
      char vr[3] = {0, 0, 0};
      if (implicit && !meta) {
        length = u32(h + 4);
      } else {
        vr[0] = static_cast<char>(h[4]);
        vr[1] = static_cast<char>(h[5]);
        // Only the standard's VRs: GDCM reads an element with another as implicit VR, taking
        // the VR's bytes for a length (hundreds of MB), or asserts on it in the meta group.
        if (!known_vr(vr))
          throw InputError(path + ": malformed DICOM: element " + hex_tag(group, element) +
                           " at offset " + std::to_string(at) +
                           " has no valid value representation");
        // GDCM reads these through typed attributes and asserts when the VR is another.
        if (const char* want = expected_vr(group, element);
            want && !(want[0] == vr[0] && want[1] == vr[1]) &&
            !(group == 0x7FE0 && std::strcmp(vr, "OW") == 0))
          throw InputError(path + ": malformed DICOM: element " + hex_tag(group, element) +
                           " at offset " + std::to_string(at) + " has VR " + vr +
                           " where the standard says " + want);
        static const char* const kLong[] = {"OB", "OD", "OF", "OL", "OV", "OW", "SQ",
                                            "SV", "UC", "UN", "UR", "UT", "UV"};
        bool long_form = false;
        for (const char* l : kLong) long_form = long_form || std::strcmp(l, vr) == 0;
        if (long_form) {
          if (!file.read(at, h, 12)) cut("element header", at, 12);
          length = u32(h + 8);
          header = 12;
        } else {
          length = u16(h + 6);
        }
      }
      const std::uint64_t value = at + header;
      const bool pixel = group == 0x7FE0 && element == 0x0010 && depth == 0;
      if (length == 0xFFFFFFFFu) {
        if (pixel) {
          encapsulated = true;
          pixel_found = true;
          pixel_at = value;
        }
        at = sequence(value, depth + 1, pixel);
        continue;
      }
      if (!file.fits(value, length))
        cut(pixel ? "pixel data " + hex_tag(group, element) : "element " + hex_tag(group, element),
            value, length);
      if (pixel) {
        pixel_found = true;
        pixel_at = value;
        pixel_length = length;
      }
      if (std::strcmp(vr, "SQ") == 0 && length > 0)
        sequence_defined(value, value + length, depth + 1);
      if (depth == 0 && group == 0x0028 && length >= 2 && length <= 16) {
        unsigned char v[16];
        file.read(value, v, static_cast<std::size_t>(length));
        if (element == 0x0010) rows = u16(v);
        if (element == 0x0011) columns = u16(v);
        if (element == 0x0100) bits = u16(v);
        if (element == 0x0101) bits_stored = u16(v);
        if (element == 0x0102) high_bit = u16(v);
        if (element == 0x0002) samples = u16(v);
        if (element == 0x0008) {
          const std::string text(reinterpret_cast<char*>(v), static_cast<std::size_t>(length));
          frames = std::max<std::int64_t>(1, std::atoll(text.c_str()));
        }
      }
      if (meta && group == 0x0002 && element == 0x0000 && length == 4) {
        unsigned char v[4];
        file.read(value, v, 4);
        meta_length = true;
        meta_length_end = value + 4 + u32(v);
      }
      if (meta && group == 0x0002 && element == 0x0010 && length <= 64) {
        char ts[65] = {};
        file.read(value, ts, static_cast<std::size_t>(length));
        std::string uid(ts);
        while (!uid.empty() && (uid.back() == ' ' || uid.back() == '\0')) uid.pop_back();
        syntax = uid;
      }
      at = value + length;
    }
    return at;
  }

  // Items of a sequence of defined length.
  void sequence_defined(std::uint64_t at, std::uint64_t end, int depth) {
    while (at < end) {
      unsigned char h[8];
      if (!file.read(at, h, 8)) cut("sequence item", at, 8);
      const std::uint32_t length = u32(h + 4);
      if (u16(h) != 0xFFFE || u16(h + 2) != 0xE000)
        throw InputError(path + ": malformed DICOM sequence at offset " + std::to_string(at));
      if (length == 0xFFFFFFFFu) {
        at = dataset(at + 8, 0, true, depth, false);
      } else {
        if (!file.fits(at + 8, length)) cut("sequence item", at + 8, length);
        dataset(at + 8, at + 8 + length, false, depth, false);
        at += 8 + length;
      }
    }
  }

  // Items of a sequence of undefined length (or encapsulated pixel data's fragments), to its
  // delimiter; returns the offset after it.
  std::uint64_t sequence(std::uint64_t at, int depth, bool fragments) {
    for (;;) {
      unsigned char h[8];
      if (!file.read(at, h, 8)) cut(fragments ? "encapsulated pixel data" : "sequence item", at, 8);
      const std::uint16_t group = u16(h), element = u16(h + 2);
      const std::uint32_t length = u32(h + 4);
      if (group == 0xFFFE && element == 0xE0DD) return at + 8;
      if (group != 0xFFFE || element != 0xE000)
        throw InputError(path + ": malformed DICOM sequence at offset " + std::to_string(at));
      if (length == 0xFFFFFFFFu && !fragments) {
        at = dataset(at + 8, 0, true, depth, false);
        continue;
      }
      if (length == 0xFFFFFFFFu || !file.fits(at + 8, length))
        cut(fragments ? "pixel data fragment" : "sequence item", at + 8, length);
      if (!fragments) dataset(at + 8, at + 8 + length, false, depth, false);
      at += 8 + length;
    }
  }

  std::string syntax;
  bool meta_length = false;  // (0002,0000) present
  std::uint64_t meta_length_end = 0;
};

// The checks of a walked data set's pixel description and data.
void check_pixels(const DicomWalk& w, const std::string& path);

}  // namespace

void check_dicom_file(const std::string& path, bool given) {
  FileBytes file(path);
  unsigned char marker[4];
  if (!file.read(128, marker, 4) || std::memcmp(marker, "DICM", 4) != 0) {
    // A data set without the preamble and meta group. GDCM reads one whose first element is in
    // explicit VR (a VR after its tag) as a slice of the series, and one in implicit VR when the
    // file is named; it sizes its allocations by the lengths it finds, and reads pixel data cut
    // short as zeros. Other files in a series' directory its scanner passes by.
    unsigned char first[8] = {};  // zeros, no VR, where the file is shorter
    file.read(0, first, 8);
    const char vr[3] = {static_cast<char>(first[4]), static_cast<char>(first[5]), 0};
    const bool explicit_vr = known_vr(vr) && (first[0] & 1) == 0;
    if (!given && !explicit_vr) {
      // GDCM's scan of the folder passes such a file by, and the series is read without it: a
      // slice at either end went missing without a word (a gap between slices is refused). A
      // file named as DICOM, or an empty one without an extension (scanners often write slices
      // without one), is a slice cut short: refused. Other files (a README) are left alone.
      const std::string lower = lower_extension(path);
      if (lower == ".dcm" || lower == ".ima" || lower == ".dicom" ||
          (lower.empty() && file.size() == 0))
        throw InputError(
            path + ": " +
            (lower.empty() ? std::string("an empty file in the DICOM series' folder")
                           : "named as DICOM but no DICOM data set GDCM reads in a folder (" +
                                 std::to_string(file.size()) + " bytes)") +
            ": a slice cut short? The series would be read without it; copy it again or move "
            "it out of the folder");
      return;
    }
    DicomWalk w{file, path};
    w.implicit = !explicit_vr;
    try {
      w.dataset(0, file.size(), false, 0, false);
    } catch (const InputError& e) {
      throw InputError(path + ": not a DICOM file (no DICM marker, and not a readable " +
                       (explicit_vr ? "explicit" : "implicit") +
                       "-VR data set: " + std::string(e.what()).substr(path.size() + 2) + ")");
    }
    check_pixels(w, path);
    return;
  }
  DicomWalk w{file, path};
  const std::uint64_t after_meta = w.dataset(132, file.size(), false, 0, true);
  // GDCM asserts on a file that ends with its meta group, or whose group length disagrees.
  if (w.meta_length && after_meta != w.meta_length_end)
    throw InputError(path + ": malformed DICOM: the file meta group length says it ends at byte " +
                     std::to_string(w.meta_length_end) + ", its elements end at " +
                     std::to_string(after_meta));
  if (after_meta >= file.size())
    throw InputError(path + ": DICOM file ends after its meta information (truncated file)");
  if (w.syntax == "1.2.840.10008.1.2.1.99") return;  // deflated: GDCM inflates and judges it
  w.implicit = w.syntax == "1.2.840.10008.1.2";
  w.big = w.syntax == "1.2.840.10008.1.2.2";
  w.dataset(after_meta, file.size(), false, 0, false);
  check_pixels(w, path);
}

namespace {

void check_pixels(const DicomWalk& w, const std::string& path) {
  // GDCM asserts on pixel descriptions outside these.
  if (w.samples != 1 && w.samples != 3 && w.samples != 4)
    throw InputError(path + ": DICOM SamplesPerPixel is " + std::to_string(w.samples) +
                     " (1, 3 or 4)");
  if (w.bits_stored >= 0 && w.bits >= 0 &&
      (w.bits_stored > w.bits || (w.high_bit >= 0 && w.high_bit >= w.bits_stored)))
    throw InputError(path + ": DICOM BitsAllocated " + std::to_string(w.bits) + ", BitsStored " +
                     std::to_string(w.bits_stored) + " and HighBit " + std::to_string(w.high_bit) +
                     " do not fit one another");
  if (w.rows < 0 && w.columns < 0) return;  // no image (GDCM says what it is)
  if (!w.pixel_found)
    throw InputError(path + ": DICOM image of " + std::to_string(w.columns) + "x" +
                     std::to_string(w.rows) + " pixels has no pixel data (truncated file?)");
  if (w.encapsulated || w.rows <= 0 || w.columns <= 0 || w.bits <= 0) return;
  const std::uint64_t bits =
      static_cast<std::uint64_t>(w.rows) * static_cast<std::uint64_t>(w.columns) *
      static_cast<std::uint64_t>(std::max<std::int64_t>(w.samples, 1)) *
      static_cast<std::uint64_t>(w.frames) * static_cast<std::uint64_t>(w.bits);
  const std::uint64_t need = (bits + 7) / 8;
  if (w.pixel_length < need)
    throw InputError(path + ": DICOM pixel data holds " + std::to_string(w.pixel_length) +
                     " bytes but " + std::to_string(w.columns) + "x" + std::to_string(w.rows) +
                     " pixels x " + std::to_string(w.frames) + " frames of " +
                     std::to_string(w.bits) + " bits need " + std::to_string(need));
}

}  // namespace

void check_dicom_input(const std::string& input) {
  std::error_code ec;
  const fs::path dir =
      fs::is_directory(input, ec) ? fs::path(input) : fs::path(input).parent_path();
  const bool file = !fs::is_directory(input, ec);
  if (file) check_dicom_file(input, true);
  for (const auto& e : fs::directory_iterator(dir.empty() ? fs::path(".") : dir, ec))
    if (e.is_regular_file(ec) && !(file && fs::equivalent(e.path(), input, ec))) {
      try {
        check_dicom_file(e.path().string(), false);
      } catch (const IoError& unreadable) {
        // GDCM's scan passes it by too, and the series was read without it (a slice at either
        // end missing without a word, in the middle called a gap).
        throw InputError(std::string(unreadable.what()) +
                         " (a file in the DICOM series' folder: GDCM would pass it by and read "
                         "the series without it; make it readable or move it out)");
      }
    }
}

}  // namespace isotile
