// `isotile info INPUT [--json]`: what a volume holds, and what `extract --iso auto` would choose.
#include "tiler/cli/commands.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <vector>

#include "core/errors.h"
#include "core/volume/image_headers.h"
#include "core/volume/itk_reader.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/volume_io.h"
#include "tiler/available_memory.h"
#include "tiler/source_histogram.h"
#include "tiler/stats_json.h"
#include "tiler/volume_source.h"

namespace isotile::cli {

namespace {

using json = StatsJson;

// Where each index axis points in LPS world space: the letter of its largest component
// (L/R along x, P/A along y, S/I along z), e.g. "LPS" for an axis-aligned NIfTI/DICOM axial scan.
std::string axis_letters(const Mat3& d) {
  std::string out;
  for (int a = 0; a < 3; ++a) {
    int best = 0;
    for (int r = 1; r < 3; ++r)
      if (std::abs(d[3 * r + a]) > std::abs(d[3 * best + a])) best = r;
    const bool plus = d[3 * best + a] > 0;
    out += "LPS"[best] == 'L'   ? (plus ? 'L' : 'R')
           : "LPS"[best] == 'P' ? (plus ? 'P' : 'A')
                                : (plus ? 'S' : 'I');
  }
  return out;
}

}  // namespace

CLI::App* add_info_command(CLI::App& app, InfoArgs& args) {
  auto* info_cmd =
      app.add_subcommand("info", "Describe a volume: dims, type, value range, histogram");
  args.in.add_to(*info_cmd);
  info_cmd->add_flag("--json", args.json, "Print JSON");
  return info_cmd;
}

int run_info(const InfoArgs& args) {
  const InputArgs& in = args.in;
  const bool as_json = args.json;
  const RawOptions raw = in.raw_options();
  const InputKind kind = input_kind(in.input);
  // A directory of several DICOM series: list them, for --series.
  if (kind == InputKind::Dicom && raw.series.empty() && std::filesystem::is_directory(in.input)) {
    check_dicom_input(in.input);  // before GDCM scans the files (image_headers.h)
    const std::vector<DicomSeriesInfo> series = list_dicom_series(in.input);
    if (series.size() > 1) {
      json list = json::array();
      for (const DicomSeriesInfo& s : series)
        list.push_back({{"uid", s.uid},
                        {"description", s.description},
                        {"dims", {s.columns, s.rows, s.files}}});
      if (as_json) {
        std::cout << json{{"input", in.input}, {"series", list}}.dump(2) << "\n";
        return 0;
      }
      std::printf("input    %s: %zu DICOM series (choose one with --series UID)\n",
                  in.input.c_str(), series.size());
      for (const DicomSeriesInfo& s : series)
        std::printf("  %s  %lld x %lld x %lld  %s\n", s.uid.c_str(),
                    static_cast<long long>(s.columns), static_cast<long long>(s.rows),
                    static_cast<long long>(s.files), s.description.c_str());
      return 0;
    }
  }
  const bool has_header =
      kind != InputKind::Raw && kind != InputKind::Field && kind != InputKind::Vdb;
  const VolumeHeader header = has_header ? read_volume_header(in.input, raw) : VolumeHeader{};
  // A volume too large to hold here is read slab by slab (twice where Otsu's bins do not give the
  // 16 bins: its range, then its bins),
  // within a quarter of what the process can have; in core it would be killed part-way through
  // the read, or refused by its allocation.
  Volume volume;
  std::unique_ptr<VolumeSource> source;
  std::uint64_t slab_budget = 0;
  // The header read above tells the size where there is one.
  const std::optional<std::uint64_t> need =
      has_header ? std::optional(checked_volume_bytes(header.type, header.dims))
                 : in_core_bytes(in.input, raw, {});
  if (need)
    if (const std::optional<AvailableMemory> available = available_memory();
        available && *need > available->without_swap) {
      slab_budget = std::max<std::uint64_t>(available->without_swap / 4, std::uint64_t{1} << 20);
      source = open_volume_source(in.input, raw);
    }
  if (!source) volume = read_volume(in.input, raw);
  // The streamed volume's frame; its samples are read slab by slab below.
  const VolumeView v =
      source ? brick_view(*source, Box3{{0, 0, 0}, source->dims}, nullptr) : volume.view();
  const std::uint64_t bytes = checked_volume_bytes(v.type, v.dims);
  // The geometry extract refuses (a negative or zero spacing, a singular direction, positions
  // float32 cannot hold): info said such a file was fine, exit 0.
  check_grid_geometry(v.dims, v.spacing, v.origin, v.world, in.input);
  ValueHistogram fine;  // Otsu's, for iso auto
  if (source) {
    for_each_slab(*source, slab_budget, nullptr, [&](const VolumeView& slab) {
      check_finite(slab, in.input);
      merge(fine, value_histogram(slab));
    });
  } else {
    fine = value_histogram(v);
  }
  const auto [lo, hi] = source ? std::pair(fine.min, fine.max) : value_range(v);
  constexpr int kBins = 16;
  std::array<std::uint64_t, kBins> hist{};
  const double width = hi > lo ? (hi - lo) / kBins : 1.0;
  // Where each of Otsu's bins holds one value (8-bit volumes, and others of values below 256 in
  // magnitude or few enough), the 16 bins are its sums; otherwise one more pass, per-plane counts
  // merged in plane order.
  bool one_value_a_bin = true;
  for (int b = 0; b < ValueHistogram::kBins && one_value_a_bin; ++b)
    one_value_a_bin = fine.count[b] == 0 || fine.lo[b] == fine.hi[b];
  const auto bin_of = [&](double value) {
    return std::clamp(static_cast<int>((value - lo) / width), 0, kBins - 1);
  };
  const auto add_bins = [&](const VolumeView& part) {
    std::vector<std::array<std::uint64_t, kBins>> planes(part.dims[2]);
    tbb::parallel_for(std::int64_t{0}, part.dims[2], [&](std::int64_t k) {
      auto& h = planes[k];
      h.fill(0);
      for (std::int64_t j = 0; j < part.dims[1]; ++j)
        for (std::int64_t i = 0; i < part.dims[0]; ++i) ++h[bin_of(part.value(i, j, k))];
    });
    for (const auto& h : planes)
      for (int b = 0; b < kBins; ++b) hist[b] += h[b];
  };
  if (one_value_a_bin) {
    for (int b = 0; b < ValueHistogram::kBins; ++b)
      if (fine.count[b] > 0) hist[bin_of(fine.lo[b])] += fine.count[b];
  } else if (source) {
    for_each_slab(*source, slab_budget, nullptr, add_bins);
  } else {
    add_bins(v);
  }
  const WorldFrame world = v.world ? *v.world : WorldFrame{v.origin, kIdentity3};

  json j;
  j["input"] = in.input;
  j["dims"] = v.dims;
  j["type"] = scalar_name(v.type);
  j["format"] = has_header ? header.format : std::string(input_kind_name(kind));
  j["spacing"] = v.spacing;
  if (has_header && !header.spacing_unit.empty()) j["spacing_unit"] = header.spacing_unit;
  j["origin"] = v.origin;
  // The world frame the mesh is written in (extract --frame world).
  j["world_origin"] = world.origin;
  j["direction"] = {{world.direction[0], world.direction[1], world.direction[2]},
                    {world.direction[3], world.direction[4], world.direction[5]},
                    {world.direction[6], world.direction[7], world.direction[8]}};
  j["orientation"] = axis_letters(world.direction);
  j["rescaled"] = header.rescaled;
  if (header.rescaled)
    j["rescale"] = {{"slope", header.rescale_slope}, {"intercept", header.rescale_intercept}};
  const RescaleRange& range = header.rescale_range;
  if (range.per_slice())
    j["rescale"] = {{"per_slice", true},
                    {"slope", {range.slope_min, range.slope_max}},
                    {"intercept", {range.intercept_min, range.intercept_max}}};
  if (!header.series_uid.empty()) {
    j["series_uid"] = header.series_uid;
    j["series_description"] = header.series_description;
  }
  j["bytes"] = bytes;
  j["min"] = lo;
  j["max"] = hi;
  json bins = json::array();
  for (int b = 0; b < kBins; ++b)
    bins.push_back({{"from", lo + b * width}, {"to", lo + (b + 1) * width}, {"count", hist[b]}});
  j["histogram"] = bins;
  // What `extract --iso auto` would choose (null for a volume of one value: no threshold).
  std::optional<double> auto_iso;
  try {
    auto_iso = otsu_isovalue(fine);
  } catch (const InputError&) {
  }
  j["iso_auto"] = auto_iso ? json(*auto_iso) : json(nullptr);
  if (const auto field = parse_field_spec(in.input))
    j["default_iso"] = field_default_iso(field->kind);
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("input    %s\n", in.input.c_str());
  std::printf("dims     %lld x %lld x %lld\n", static_cast<long long>(v.dims[0]),
              static_cast<long long>(v.dims[1]), static_cast<long long>(v.dims[2]));
  std::printf("type     %s (%zu bytes)\n", std::string(scalar_name(v.type)).c_str(),
              static_cast<std::size_t>(bytes));
  std::printf(
      "spacing  %g, %g, %g%s\n", v.spacing[0], v.spacing[1], v.spacing[2],
      has_header && !header.spacing_unit.empty() ? (" " + header.spacing_unit).c_str() : "");
  std::printf("format   %s\n", j["format"].get<std::string>().c_str());
  if (!header.series_uid.empty())
    std::printf("series   %s  %s\n", header.series_uid.c_str(), header.series_description.c_str());
  std::printf("origin   %g, %g, %g\n", v.origin[0], v.origin[1], v.origin[2]);
  std::printf(
      "world    origin %g, %g, %g; axes toward %s (LPS); direction columns (%g, %g, %g) "
      "(%g, %g, %g) (%g, %g, %g)\n",
      world.origin[0], world.origin[1], world.origin[2], axis_letters(world.direction).c_str(),
      world.direction[0], world.direction[3], world.direction[6], world.direction[1],
      world.direction[4], world.direction[7], world.direction[2], world.direction[5],
      world.direction[8]);
  if (range.per_slice())
    std::printf(
        "rescale  per slice: value = stored x %g..%g + %g..%g, each slice by its own (range and "
        "histogram in these units)\n",
        range.slope_min, range.slope_max, range.intercept_min, range.intercept_max);
  else if (header.rescaled)
    std::printf("rescale  value = stored x %g + %g (range and histogram in these units)\n",
                header.rescale_slope, header.rescale_intercept);
  std::printf("range    %g .. %g\n", lo, hi);
  std::printf("histogram\n");
  for (int b = 0; b < kBins; ++b)
    std::printf("  %12g .. %-12g %llu\n", lo + b * width, lo + (b + 1) * width,
                static_cast<unsigned long long>(hist[b]));
  if (auto_iso)
    std::printf("iso auto %s (Otsu's threshold: what extract --iso auto chooses)\n",
                number_text(*auto_iso).c_str());
  return 0;
}

}  // namespace isotile::cli
