// TIFF page directories walked before ITK reads the file (image_headers.h).
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/volume/file_bytes.h"
#include "core/volume/image_headers.h"
#include "core/volume/imagej_description.h"

namespace isotile {

using file_check::FileBytes;
using file_check::get;

namespace {

// The sample type of a page of one gray sample per pixel, as ITK reads it.
std::optional<ScalarType> tiff_sample_type(std::uint64_t bits, std::uint64_t format) {
  if (format == 3) {
    if (bits == 32) return ScalarType::Float32;
    if (bits == 64) return ScalarType::Float64;
    return std::nullopt;
  }
  if (format != 1 && format != 2) return std::nullopt;
  const bool sign = format == 2;
  if (bits == 8) return sign ? ScalarType::Int8 : ScalarType::UInt8;
  if (bits == 16) return sign ? ScalarType::Int16 : ScalarType::UInt16;
  if (bits == 32) return sign ? ScalarType::Int32 : ScalarType::UInt32;
  return std::nullopt;
}

// The array shape tifffile writes in its description of a series' first page ({"shape": [5, 2,
// 6, 8], ...}); empty where the description is not one.
std::vector<std::uint64_t> tifffile_shape(const std::string& description) {
  std::vector<std::uint64_t> shape;
  if (description.empty() || description[0] != '{') return shape;
  std::size_t at = description.find("\"shape\"");
  if (at == std::string::npos || (at = description.find('[', at)) == std::string::npos)
    return shape;
  std::uint64_t v = 0;
  bool digits = false;
  for (++at; at < description.size() && description[at] != ']'; ++at) {
    const char c = description[at];
    if (c >= '0' && c <= '9' && v < (std::uint64_t{1} << 40)) {
      v = v * 10 + static_cast<std::uint64_t>(c - '0');
      digits = true;
    } else if (c == ',' && digits) {
      shape.push_back(v);
      v = 0;
      digits = false;
    }
  }
  if (digits) shape.push_back(v);
  return shape;
}

}  // namespace

TiffCheck check_tiff_file(const std::string& path) {
  TiffCheck result;
  FileBytes file(path);
  unsigned char h[16];
  if (!file.read(0, h, 8))
    throw InputError(path + ": not a TIFF file (" + std::to_string(file.size()) + " bytes)");
  const bool little = h[0] == 'I' && h[1] == 'I';
  if (!little && !(h[0] == 'M' && h[1] == 'M'))
    throw InputError(path + ": not a TIFF file (no II or MM byte-order mark)");
  const bool swap = little != (std::endian::native == std::endian::little);
  const std::uint16_t version = get<std::uint16_t>(h + 2, swap);
  if (version != 42 && version != 43)
    throw InputError(path + ": not a TIFF file (version " + std::to_string(version) + ")");
  const bool big = version == 43;
  std::uint64_t ifd = 0;
  if (big) {
    if (!file.read(0, h, 16)) throw InputError(path + ": BigTIFF header truncated");
    ifd = get<std::uint64_t>(h + 8, swap);
  } else {
    ifd = get<std::uint32_t>(h + 4, swap);
  }
  const auto cut = [&](int page, const std::string& what, std::uint64_t at, std::uint64_t n) {
    throw InputError(path + ": TIFF page " + std::to_string(page) + ": " + what + " needs " +
                     std::to_string(n) + " bytes from offset " + std::to_string(at) +
                     " but the file holds " + std::to_string(file.size()) +
                     " bytes (truncated file)");
  };
  static const std::size_t kTypeSize[19] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4,
                                            8, 4, 8, 4, 0, 0, 8, 8, 8};
  std::vector<std::uint64_t> seen;
  std::vector<std::uint64_t> first_series;    // tifffile's shape of page 1's series
  std::array<std::uint64_t, 4> first{};       // page 1's width, height, bits and samples
  std::array<std::uint64_t, 3> first_kind{};  // its photometric, planar configuration, format
  // Whether every page so far holds its samples uncompressed, as rows of one gray sample, in
  // strips that follow each other and the previous page's (ImageJ writes its stacks so), and
  // where they start and end: then the file reads box by box like a raw file.
  bool plain = true;
  std::optional<ScalarType> plain_type;
  std::uint64_t plain_start = 0, plain_end = 0;
  std::uint64_t imagej_images = 1;  // page 1's `images=`: ImageJ's count of planes
  int page = 0;
  while (ifd != 0) {
    ++page;
    if (std::find(seen.begin(), seen.end(), ifd) != seen.end() || page > 1000000)
      throw InputError(path + ": TIFF page directories form a loop");
    seen.push_back(ifd);
    const std::size_t count_size = big ? 8 : 2, entry_size = big ? 20 : 12,
                      inline_size = big ? 8 : 4;
    if (!file.read(ifd, h, count_size)) cut(page, "its directory", ifd, count_size);
    const std::uint64_t entries = big ? get<std::uint64_t>(h, swap) : get<std::uint16_t>(h, swap);
    if (!file.fits(ifd + count_size, entries * entry_size + inline_size))
      cut(page, "its directory", ifd, count_size + entries * entry_size + inline_size);
    std::uint64_t width = 0, height = 0, bps = 1, spp = 1, compression = 1, rows_per_strip = 0,
                  tile_w = 0, tile_h = 0, subfile = 0, photometric = 1, planar = 1, format = 1,
                  orientation = 1;
    std::vector<std::uint64_t> offsets, counts;
    std::string description;
    double x_resolution = 0, y_resolution = 0;  // pixels per unit (0: not given)
    std::uint64_t resolution_unit = 2;          // TIFF's default: the inch
    for (std::uint64_t e = 0; e < entries; ++e) {
      unsigned char d[20];
      const std::uint64_t at = ifd + count_size + e * entry_size;
      file.read(at, d, entry_size);
      const std::uint16_t tag = get<std::uint16_t>(d, swap), type = get<std::uint16_t>(d + 2, swap);
      const std::uint64_t n =
          big ? get<std::uint64_t>(d + 4, swap) : get<std::uint32_t>(d + 4, swap);
      const std::size_t size = type < 19 ? kTypeSize[type] : 0;
      // ITK lists every custom tag through TIFFGetField with one pointer, where libtiff's
      // DotRange takes two: ITK then writes through a stray pointer (found by the fuzz replay).
      if (tag == 336)
        throw InputError(path + ": TIFF page " + std::to_string(page) +
                         " has a DotRange tag, which ITK's TIFF reader cannot read safely");
      // libtiff declares DateTime 20 characters long and keeps what the file holds; ITK copies
      // 20 from it whatever the count (a heap over-read, found by the fuzz replay under ASan).
      if (tag == 306 && n < 20)
        throw InputError(path + ": TIFF page " + std::to_string(page) + "'s DateTime holds " +
                         std::to_string(n) + " characters where TIFF says 20");
      if (size == 0) continue;  // unknown types are skipped by libtiff too
      if (n > (std::uint64_t{1} << 40) / size)
        throw InputError(path + ": TIFF page " + std::to_string(page) + ": tag " +
                         std::to_string(tag) + " claims " + std::to_string(n) + " values");
      const std::uint64_t bytes = n * size;
      std::uint64_t where = at + (big ? 12 : 8);
      if (bytes > inline_size) {
        where = big ? get<std::uint64_t>(d + 12, swap) : get<std::uint32_t>(d + 8, swap);
        if (!file.fits(where, bytes))
          cut(page, "tag " + std::to_string(tag) + "'s values", where, bytes);
      }
      const auto value = [&](std::uint64_t i) -> std::uint64_t {
        unsigned char v[8];
        file.read(where + i * size, v, size);
        if (size == 2) return get<std::uint16_t>(v, swap);
        if (size == 4) return get<std::uint32_t>(v, swap);
        if (size == 8) return get<std::uint64_t>(v, swap);
        return v[0];
      };
      if (n == 0) continue;
      switch (tag) {
        case 254:
          subfile |= value(0);
          break;
        case 255:  // the old SubfileType: 2 is a reduced-resolution image, as libtiff maps it
          if (value(0) == 2) subfile |= 1;
          break;
        case 262:
          photometric = value(0);
          break;
        case 274:
          orientation = value(0);
          break;
        case 284:
          planar = value(0);
          break;
        case 339:
          format = value(0);
          break;
        case 256:
          width = value(0);
          break;
        case 257:
          height = value(0);
          break;
        case 258:
          bps = value(0);
          break;
        case 259:
          compression = value(0);
          break;
        case 277:
          spp = value(0);
          break;
        case 278:
          rows_per_strip = value(0);
          break;
        case 322:
          tile_w = value(0);
          break;
        case 323:
          tile_h = value(0);
          break;
        case 282:
        case 283:
          if (type == 5) {  // a rational: two unsigned 32-bit integers
            unsigned char r[8];
            file.read(where, r, 8);
            const std::uint32_t num = get<std::uint32_t>(r, swap),
                                den = get<std::uint32_t>(r + 4, swap);
            (tag == 282 ? x_resolution : y_resolution) = den ? double(num) / den : 0;
          }
          break;
        case 296:
          resolution_unit = value(0);
          break;
        case 270:  // ImageDescription, where ImageJ and tifffile say what the pages are
          if (size == 1 && n <= (1u << 20)) {
            description.resize(n);
            file.read(where, description.data(), n);
            description.resize(std::strlen(description.c_str()));
          }
          break;
        case 273:
        case 324:
          if (n > (std::uint64_t{1} << 24))
            throw InputError(path + ": TIFF page " + std::to_string(page) + ": " +
                             std::to_string(n) + " strips");
          offsets.resize(n);
          for (std::uint64_t i = 0; i < n; ++i) offsets[i] = value(i);
          break;
        case 279:
        case 325:
          if (n > (std::uint64_t{1} << 24))
            throw InputError(path + ": TIFF page " + std::to_string(page) + ": " +
                             std::to_string(n) + " strips");
          counts.resize(n);
          for (std::uint64_t i = 0; i < n; ++i) counts[i] = value(i);
          break;
        default:
          break;
      }
    }
    if (offsets.size() != counts.size())
      throw InputError(path + ": TIFF page " + std::to_string(page) + " has " +
                       std::to_string(offsets.size()) + " strip offsets but " +
                       std::to_string(counts.size()) + " byte counts");
    std::uint64_t held = 0;
    for (std::size_t i = 0; i < offsets.size(); ++i) {
      if (!file.fits(offsets[i], counts[i]))
        cut(page, (tile_w ? "tile " : "strip ") + std::to_string(i), offsets[i], counts[i]);
      held += counts[i];
    }
    if (compression == 1 && width > 0 && height > 0 && width < (1u << 30) && height < (1u << 30) &&
        bps <= 64 && spp <= 64) {
      std::uint64_t need = 0;
      if (tile_w && tile_h) {
        const std::uint64_t across = (width + tile_w - 1) / tile_w,
                            down = (height + tile_h - 1) / tile_h;
        need = across * down * ((tile_w * spp * bps + 7) / 8) * tile_h;
      } else {
        const std::uint64_t rows =
            rows_per_strip && rows_per_strip < height ? rows_per_strip : height;
        const std::uint64_t row_bytes = (width * spp * bps + 7) / 8;
        // The last strip may be short.
        need = row_bytes * height;
        (void)rows;
      }
      if (held < need)
        throw InputError(path + ": TIFF page " + std::to_string(page) + " of " +
                         std::to_string(width) + "x" + std::to_string(height) + " " +
                         std::to_string(bps) + "-bit samples needs " + std::to_string(need) +
                         " bytes but its strips hold " + std::to_string(held));
    }
    // Rows top to bottom, left to right (orientation 1), of gray values where 0 is black: what
    // ITK reads into its buffer as the samples are stored (it applies none of these tags).
    const std::optional<ScalarType> type = tiff_sample_type(bps, format);
    plain = plain && compression == 1 && !tile_w && spp == 1 && photometric == 1 &&
            orientation == 1 && type && (page == 1 || type == plain_type) && !offsets.empty() &&
            held == (width * bps / 8) * height && (page == 1 || offsets[0] == plain_end);
    for (std::size_t i = 1; plain && i < offsets.size(); ++i)
      plain = offsets[i] == offsets[i - 1] + counts[i - 1];
    if (plain) {
      if (page == 1) plain_start = offsets[0];
      plain_type = type;
      plain_end = offsets[0] + held;
    }
    // ITK sizes its buffer by the first page and reads every page into it: pages of another
    // size, or reduced-resolution and mask pages it counts differently, would overrun it.
    if (subfile & 5)
      throw InputError(path + ": TIFF page " + std::to_string(page) +
                       " is a reduced-resolution or mask image (NewSubfileType " +
                       std::to_string(subfile) + "); a volume is a stack of full pages");
    // What ITK 5.2's TIFF reader reads as a volume: one gray sample per pixel (it reads the first
    // `width` samples of each row of several, interleaved), of 8 or 16-bit integers or 32-bit
    // floats (it takes 32-bit integers, reads none of their samples, and isotile reads them
    // itself where they lie plainly: volume_io.cpp), in strips (tiled pages it reads as colour).
    if (tile_w || tile_h)
      throw InputError(path + ": TIFF page " + std::to_string(page) + " is stored in tiles of " +
                       std::to_string(tile_w) + "x" + std::to_string(tile_h) +
                       ", which ITK's TIFF reader reads as colour; save the pages in strips (as "
                       "ImageJ and most tools do by default)");
    // Orientations other than top-left (1) and bottom-left (4) send ITK's reader through
    // libtiff's colour path: a gray page was refused as "4 components per sample (colour)".
    if (orientation != 1 && orientation != 4) {
      static const char* const kOrientation[] = {
          "",         "",          "top-right",    "bottom-right", "",
          "left-top", "right-top", "right-bottom", "left-bottom"};
      throw InputError(path + ": TIFF page " + std::to_string(page) + " has Orientation " +
                       std::to_string(orientation) +
                       (orientation <= 8 && *kOrientation[orientation]
                            ? std::string(" (") + kOrientation[orientation] + ")"
                            : std::string()) +
                       ", which ITK's TIFF reader reads as colour; save the pages top-left "
                       "(Orientation 1, the default of ImageJ and most tools)");
    }
    const std::vector<std::uint64_t> series = tifffile_shape(description);
    if (page == 1) {
      // ImageJ describes the file on its first page.
      const std::map<std::string, std::string> imagej = imagej_properties(description);
      const ImageJShape shape = imagej_shape(imagej);
      imagej_images = shape.images;
      result.calibration =
          imagej_spacing(path, imagej, x_resolution, y_resolution, resolution_unit);
      if (spp != 1)
        throw InputError(
            path + ": TIFF pages hold " + std::to_string(spp) + " samples per pixel (" +
            (photometric == 2 || photometric == 6 ? "colour" : "channels, or gray and alpha") +
            "); a volume needs one gray sample per pixel");
      if (!type || type == ScalarType::Float64)
        throw InputError(path + ": " + std::to_string(bps) + "-bit" +
                         (format == 3   ? " floating-point"
                          : format == 2 ? " signed"
                                        : "") +
                         " TIFF samples cannot be read as a volume (8, 16 or 32-bit integers, or "
                         "32-bit floats; ITK's TIFF reader has no other)");
      // tifffile's own description: an array of more axes than z, y, x laid out as pages (z
      // and channels interleaved, or time points one after another) is not one volume.
      if (std::count_if(series.begin(), series.end() - std::min<std::size_t>(series.size(), 2),
                        [](std::uint64_t n) { return n > 1; }) > 1) {
        std::string text;
        for (const std::uint64_t d : series) text += (text.empty() ? "" : ", ") + std::to_string(d);
        throw InputError(path + ": tifffile wrote an array of shape [" + text +
                         "] here, whose pages interleave more axes than z (channels or time "
                         "points); a volume is one 3-D array: save each one on its own");
      }
      if (shape.hyperstack())
        throw InputError(
            path + ": an ImageJ hyperstack of " +
            (shape.channels > 1 ? std::to_string(shape.channels) + " channels" : "") +
            (shape.channels > 1 && shape.frames > 1 ? " and " : "") +
            (shape.frames > 1 ? std::to_string(shape.frames) + " time points" : "") +
            ", not one volume: a volume is one channel at one time point (split it in ImageJ "
            "first: Image > Color > Split Channels, Image > Hyperstacks > Reduce "
            "Dimensionality)");
    }
    // A later page that begins a series of its own (tifffile writes each series' shape on its
    // first page) where page 1 began a 3-D one, or of another shape: two arrays in one file,
    // which ITK would stack as one volume. Series of one plane each, alike, are a stack of planes
    // (tifffile's TiffWriter writes a loop of slices so).
    if (page == 1) first_series = series;
    if (page > 1 && !series.empty() && (series != first_series || first_series.size() > 2))
      throw InputError(path + ": TIFF page " + std::to_string(page) +
                       " begins a second series (tifffile's description says so); a volume is "
                       "one series: save each one in a file of its own");
    if (page == 1) {
      first = {width, height, bps, spp};
      first_kind = {photometric, planar, format};
    } else if (std::array<std::uint64_t, 3>{photometric, planar, format} != first_kind) {
      throw InputError(path + ": TIFF page " + std::to_string(page) +
                       " stores its samples differently from page 1 (photometric " +
                       std::to_string(photometric) + ", planar " + std::to_string(planar) +
                       ", sample format " + std::to_string(format) + " against " +
                       std::to_string(first_kind[0]) + ", " + std::to_string(first_kind[1]) + ", " +
                       std::to_string(first_kind[2]) + ")");
    } else if (std::array<std::uint64_t, 4>{width, height, bps, spp} != first) {
      throw InputError(path + ": TIFF page " + std::to_string(page) + " is " +
                       std::to_string(width) + "x" + std::to_string(height) + " with " +
                       std::to_string(spp) + " samples of " + std::to_string(bps) +
                       " bits where page 1 is " + std::to_string(first[0]) + "x" +
                       std::to_string(first[1]) + " with " + std::to_string(first[3]) +
                       " samples of " + std::to_string(first[2]) + " bits");
    }
    const std::uint64_t next_at = ifd + count_size + entries * entry_size;
    unsigned char nx[8];
    file.read(next_at, nx, inline_size);
    ifd = big ? get<std::uint64_t>(nx, swap) : get<std::uint32_t>(nx, swap);
  }
  // One page directory whose description counts more images: ImageJ's layout for stacks past
  // 4 GiB (and tifffile's imagej=True with truncate=True), the planes stored one after another
  // from the first page's samples on, as ImageJ and Fiji read it. ITK sees one page; isotile
  // reads the planes itself.
  std::int64_t planes = page;
  if (page == 1 && imagej_images > 1) {
    const std::uint64_t plane = plain_end - plain_start;
    if (!plain)
      throw InputError(path + ": an ImageJ stack of " + std::to_string(imagej_images) +
                       " images in one page directory (as ImageJ writes stacks past 4 GiB), whose "
                       "samples are not stored plainly (uncompressed gray strips), so their "
                       "planes cannot be found; save it with a directory per page");
    if (imagej_images > file.size() / std::max<std::uint64_t>(plane, 1) ||
        !file.fits(plain_start, plane * imagej_images))
      throw InputError(path + ": an ImageJ stack of " + std::to_string(imagej_images) +
                       " images in one page directory needs " +
                       std::to_string(plane * imagej_images) + " bytes of samples from offset " +
                       std::to_string(plain_start) + " but the file holds " +
                       std::to_string(file.size()) + " bytes (truncated file)");
    planes = static_cast<std::int64_t>(imagej_images);
    result.imagej_planes = true;
  }
  if (!plain || page == 0) return result;
  PlainData& data = result.plain.emplace();
  data.file = path;
  data.offset = plain_start;
  data.type = *plain_type;
  data.dims = {static_cast<std::int64_t>(first[0]), static_cast<std::int64_t>(first[1]), planes};
  data.endian = little ? Endian::Little : Endian::Big;
  data.bytes_after = true;  // the later pages' directories may follow the samples
  return result;
}

}  // namespace isotile
