#include "tiler/brick_plan.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <optional>
#include <string>

#include "core/errors.h"
#include "core/file_names.h"

namespace isotile {

Box3 BrickPlan::cells(std::int64_t b) const {
  const std::int64_t idx[3] = {b % count[0], b / count[0] % count[1], b / count[0] / count[1]};
  Box3 box;
  for (int a = 0; a < 3; ++a) {
    box.lo[a] = idx[a] * brick[a];
    box.hi[a] = std::min(box.lo[a] + brick[a], dims[a] - 1);
  }
  return box;
}

std::int64_t BrickPlan::owner(int axis, std::int64_t v) const {
  return std::min(v / brick[axis], count[axis] - 1);
}

std::uint64_t brick_bytes(const Index3& cells, const BrickPlanOptions& o) {
  double samples = 1, n_cells = 1;
  for (int a = 0; a < 3; ++a) {
    std::int64_t extent = cells[a] + 1 + 2 * static_cast<std::int64_t>(o.halo);
    if (o.volume_dims[a] > 0) extent = std::min(extent, o.volume_dims[a]);
    samples *= static_cast<double>(extent);
    n_cells *= static_cast<double>(cells[a]);
  }
  const double bytes = samples * (static_cast<double>(o.sample_bytes) * o.sample_buffers + 1.0 / 8 +
                                  o.state_bytes_per_sample) +
                       n_cells * o.output_bytes_per_cell + static_cast<double>(o.fixed_bytes);
  return bytes >= 1.8e19 ? ~std::uint64_t{0} : static_cast<std::uint64_t>(bytes);
}

namespace {
// Thinnest y-z extent of a brick spanning whole rows before cubes are preferred: with a halo of
// 2 samples, 64 cells keep the halo overhead under about 15%.
constexpr std::int64_t kMinRowBrick = 64;
}  // namespace

namespace {

// Bytes of the least brick: one cell, or for slabs one cell layer (the budget below which
// plan_within() has no plan).
std::uint64_t least_brick_bytes(const Index3& dims, const BrickPlanOptions& options) {
  Index3 c;
  for (int a = 0; a < 3; ++a)
    c[a] = options.slabs && a < 2 ? std::max<std::int64_t>(dims[a] - 1, 1) : 1;
  return brick_bytes(c, options);
}

BrickPlan plan_within(const Index3& dims, const BrickPlanOptions& options) {
  BrickPlan plan;
  plan.dims = dims;
  Index3 cells;
  for (int a = 0; a < 3; ++a) cells[a] = std::max<std::int64_t>(dims[a] - 1, 1);
  // Largest side s with per-axis clamping that fits; brick_bytes grows with s. `full_x` keeps
  // whole rows: the output file orders records x fastest, so a brick spanning x writes the rows
  // of each z-plane as one contiguous run instead of one write per row.
  auto shape = [&](std::int64_t s, bool full_x) {
    Index3 c;
    for (int a = 0; a < 3; ++a)
      c[a] = (options.slabs && a < 2) || (full_x && a == 0) ? cells[a] : std::min(s, cells[a]);
    return c;
  };
  auto largest = [&](bool full_x) {
    std::int64_t lo = 0, hi = *std::max_element(cells.begin(), cells.end());
    while (lo < hi) {
      const std::int64_t mid = lo + (hi - lo + 1) / 2;
      if (brick_bytes(shape(mid, full_x), options) <= options.memory)
        lo = mid;
      else
        hi = mid - 1;
    }
    return lo;  // 0: not even one cell fits
  };
  if (largest(false) == 0)
    throw InputError("memory budget of " + std::to_string(options.memory) +
                     " bytes is too small: one " +
                     (options.slabs ? "slab of one cell layer" : "brick of one cell") + " needs " +
                     std::to_string(least_brick_bytes(dims, options)) + " bytes");
  const auto plan_of = [&](const Index3& c) {
    BrickPlan p = plan;
    for (int a = 0; a < 3; ++a) {
      p.count[a] = (cells[a] + c[a] - 1) / c[a];
      // Even out: the same number of bricks, each as equal as possible (never larger than c).
      p.brick[a] = (cells[a] + p.count[a] - 1) / p.count[a];
      p.count[a] = (cells[a] + p.brick[a] - 1) / p.brick[a];
    }
    return p;
  };
  // Whole rows when that still leaves bricks thick enough for a small halo overhead (or whole
  // y-z extents); cubes otherwise, which have the least halo per cell.
  const std::int64_t rows = largest(true);
  const bool full_x = rows >= std::min<std::int64_t>(kMinRowBrick, std::min(cells[1], cells[2]));
  const BrickPlan cubes = plan_of(shape(largest(false), false));
  // Many columns of cubes can hold more outside the budget than a brick inside it (2048 x 2048 x
  // 512 at 16 MiB: 17 columns, 285 MB of the plain tiler's tables, a peak of 299 MiB; in whole
  // rows 43 MiB).
  if (!full_x && rows > 0 && cubes.count[0] > 1 &&
      static_cast<double>(options.column_bytes) * static_cast<double>(cubes.count[0]) >
          kColumnShare * static_cast<double>(options.memory)) {
    const BrickPlan thin_rows = plan_of(shape(rows, true));
    if (options.max_read_amplification <= 0 ||
        read_amplification(thin_rows, options.halo) <= options.max_read_amplification)
      return thin_rows;
  }
  if (!full_x) return cubes;
  // Unless the halo is so large against the rows' y-z section that they read the volume many
  // times more over than cubes would (Macet max's 138 samples: 2048x300x300 float32 at 1.5653 GB
  // read 16.4 times over in rows, 1.27 in cubes); rows also where they read a quarter more.
  const BrickPlan row_plan = plan_of(shape(rows, true));
  if (read_amplification(row_plan, options.halo) > 1.25 * read_amplification(cubes, options.halo))
    return cubes;
  return row_plan;
}

// A plan within `options.memory` that reads the volume at most max_read_amplification times
// over, or none.
std::optional<BrickPlan> feasible_plan(const Index3& dims, const BrickPlanOptions& options) {
  std::optional<BrickPlan> plan;
  try {
    plan = plan_within(dims, options);
  } catch (const InputError&) {
    return std::nullopt;
  }
  if (options.max_read_amplification > 0 &&
      read_amplification(*plan, options.halo) > options.max_read_amplification)
    return std::nullopt;
  return plan;
}

// A volume of no samples, a negative halo or samples of no bytes plan nothing sensible (dims
// 0x0x0 "would read the volume -9223372036854775808 times over"), and more samples than an
// int64 counts overflow the bricks' count.
void check_plan_input(const Index3& dims, const BrickPlanOptions& options) {
  for (int a = 0; a < 3; ++a)
    if (dims[a] < 1)
      throw InputError("brick plan: the volume's dims must be positive, got " +
                       std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" +
                       std::to_string(dims[2]));
  if (options.halo < 0 || options.sample_bytes == 0 || options.sample_buffers < 1)
    throw InputError("brick plan: a negative halo, samples of 0 bytes or no sample buffer");
  checked_volume_bytes(ScalarType::UInt8, dims);  // CapacityError past an int64 of samples
}

}  // namespace

std::uint64_t least_memory(const Index3& dims, BrickPlanOptions options) {
  check_plan_input(dims, options);
  // A budget for the whole volume as one brick always plans (it reads the volume once); below
  // it, plans only grow more feasible with the budget, so a bisection finds the least.
  Index3 cells;
  for (int a = 0; a < 3; ++a) cells[a] = std::max<std::int64_t>(dims[a] - 1, 1);
  std::uint64_t lo = 0, hi = brick_bytes(cells, options);
  while (lo + 1 < hi) {
    const std::uint64_t mid = lo + (hi - lo) / 2;
    options.memory = mid;
    (feasible_plan(dims, options) ? hi : lo) = mid;
  }
  return hi;
}

BrickPlan plan_bricks(const Index3& dims, const BrickPlanOptions& options) {
  check_plan_input(dims, options);
  std::optional<BrickPlan> plan;
  std::string one_cell;  // plan_within's refusal: not even the least brick fits
  try {
    plan = plan_within(dims, options);
  } catch (const InputError& e) {
    one_cell = e.what();
  }
  const double amplification = plan ? read_amplification(*plan, options.halo) : 0;
  if (plan &&
      (options.max_read_amplification <= 0 || amplification <= options.max_read_amplification))
    return *plan;
  // Each refusal names the least budget that plans, so that the budget it names runs.
  const std::uint64_t least = least_memory(dims, options);
  const std::string limit =
      std::to_string(static_cast<std::int64_t>(options.max_read_amplification));
  if (!plan) {
    if (least == least_brick_bytes(dims, options)) throw InputError(one_cell);
    throw InputError(one_cell + "; give at least " + std::to_string(least) +
                     " bytes (bricks that small, each read with its halo of " +
                     std::to_string(options.halo) + " samples, would read the volume more than " +
                     limit + " times over)");
  }
  auto text = [](const Index3& v) {
    return std::to_string(v[0]) + "x" + std::to_string(v[1]) + "x" + std::to_string(v[2]);
  };
  throw InputError("memory budget of " + std::to_string(options.memory) +
                   " bytes is too small for a halo of " + std::to_string(options.halo) +
                   " samples: its " + std::to_string(plan->total()) + " bricks of " +
                   text(plan->brick) + " cells, each read with its halo, would read the volume " +
                   std::to_string(static_cast<std::int64_t>(std::ceil(amplification))) +
                   " times over (at most " + limit + "); give at least " + std::to_string(least) +
                   " bytes");
}

double read_amplification(const BrickPlan& plan, int halo) {
  double total = 1;
  for (int a = 0; a < 3; ++a) {
    double read = 0;
    for (std::int64_t i = 0; i < plan.count[a]; ++i) {
      const std::int64_t lo = i * plan.brick[a];
      const std::int64_t hi = std::min(lo + plan.brick[a], plan.dims[a] - 1);
      read += static_cast<double>(std::min(hi + 1 + halo, plan.dims[a]) -
                                  std::max<std::int64_t>(lo - halo, 0));
    }
    total *= read / static_cast<double>(plan.dims[a]);
  }
  return total;
}

std::uint64_t parse_memory_size(const std::string& text) {
  // Digits with at most one decimal point, then the unit: std::stod alone also took hex
  // ("0x1000"), exponents ("1e3K") and leading blanks.
  std::size_t used = 0;
  bool point = false, digit = false;
  for (; used < text.size(); ++used) {
    const char c = text[used];
    if (c >= '0' && c <= '9') {
      digit = true;
    } else if (c == '.' && !point) {
      point = true;
    } else {
      break;
    }
  }
  double value = 0;
  // from_chars, not strtod: the C locale's point whatever the process's locale (Qt sets the
  // user's in MeshLab, where a comma-point locale made strtod stop at the '.').
  if (!digit || std::from_chars(text.data(), text.data() + used, value).ptr != text.data() + used)
    used = 0;
  const std::string unit = ascii_lower(text.substr(used));
  double scale = 0;
  if (unit.empty() || unit == "b")
    scale = 1;
  else if (unit == "k" || unit == "kib")
    scale = 1024.0;
  else if (unit == "m" || unit == "mib")
    scale = 1024.0 * 1024;
  else if (unit == "g" || unit == "gib")
    scale = 1024.0 * 1024 * 1024;
  else if (unit == "t" || unit == "tib")
    scale = 1024.0 * 1024 * 1024 * 1024;
  else if (unit == "kb")
    scale = 1e3;
  else if (unit == "mb")
    scale = 1e6;
  else if (unit == "gb")
    scale = 1e9;
  else if (unit == "tb")
    scale = 1e12;
  // Below one byte ("0.5") is no budget either, rather than one of 0 bytes.
  if (used == 0 || scale == 0 || !(value * scale >= 1))
    throw InputError("bad memory size '" + text +
                     "': expected a positive number with an optional unit (B, K or KiB, M or MiB, "
                     "G or GiB, T or TiB; KB, MB, GB, TB), e.g. 256MiB");
  if (!std::isfinite(value * scale) || value * scale >= 1.8e19)
    throw InputError("memory size '" + text + "' is more bytes than isotile counts (at most " +
                     "1.8e19, 16 EiB)");
  // A whole number of bytes exactly (through a double, 2^63 - 1 became 2^63).
  std::uint64_t whole = 0;
  if (!point && std::from_chars(text.data(), text.data() + used, whole).ptr == text.data() + used &&
      scale == std::floor(scale)) {
    const auto factor = static_cast<std::uint64_t>(scale);
    if (whole <= UINT64_MAX / factor) return whole * factor;
  }
  return static_cast<std::uint64_t>(value * scale);
}

}  // namespace isotile
