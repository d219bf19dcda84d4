#include "tiler/available_memory.h"

#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

#include "core/errors.h"
#include "core/volume/procedural_fields.h"
#include "core/volume/scalar_type.h"

namespace isotile {

namespace {

constexpr std::uint64_t kNoLimit = std::numeric_limits<std::uint64_t>::max();

// "Key:   123 kB" lines of /proc/meminfo or /proc/self/status, in bytes.
std::optional<std::uint64_t> proc_kb(const char* file, const std::string& key) {
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) {
    if (line.compare(0, key.size() + 1, key + ":") != 0) continue;
    std::istringstream s(line.substr(key.size() + 1));
    std::uint64_t kb = 0;
    if (s >> kb) return kb * 1024;
    return std::nullopt;
  }
  return std::nullopt;
}

std::optional<std::uint64_t> file_number(const std::string& path) {
  std::ifstream in(path);
  std::string text;
  if (!(in >> text) || text == "max") return std::nullopt;
  try {
    std::size_t used = 0;
    const unsigned long long v = std::stoull(text, &used);
    if (used != text.size()) return std::nullopt;
    return v;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

// "key value" lines of a control group's memory.stat.
std::uint64_t stat_value(const std::string& path, const std::string& key) {
  std::ifstream in(path);
  std::string k;
  std::uint64_t v = 0;
  while (in >> k >> v)
    if (k == key) return v;
  return 0;
}

// What the control group leaves: its limit less what it uses, where the inactive file pages
// (page cache the kernel drops before it reclaims anything else) count as free, as MemAvailable
// counts them. cgroup v2 walks up from the process's group (a parent's limit binds too); v1
// reads the memory controller's group, or its mount's root inside a container.
std::uint64_t cgroup_left() {
  std::ifstream in("/proc/self/cgroup");
  std::string line, v2, v1;
  while (std::getline(in, line)) {
    if (line.rfind("0::", 0) == 0) v2 = line.substr(3);
    const std::size_t at = line.find(":memory:");
    if (at != std::string::npos) v1 = line.substr(at + 8);
  }
  std::uint64_t left = kNoLimit;
  auto take = [&](const std::optional<std::uint64_t>& limit, std::uint64_t used,
                  std::uint64_t inactive) {
    // cgroup v1 says "no limit" with a number near 2^63.
    if (!limit || *limit >= (std::uint64_t{1} << 62)) return;
    const std::uint64_t busy = used > inactive ? used - inactive : 0;
    left = std::min(left, *limit > busy ? *limit - busy : 0);
  };
  if (!v2.empty() && v2 != "/") {
    for (std::string dir = v2; !dir.empty() && dir != "/";
         dir = dir.substr(0, dir.find_last_of('/'))) {
      const std::string base = "/sys/fs/cgroup" + dir;
      take(file_number(base + "/memory.max"), file_number(base + "/memory.current").value_or(0),
           stat_value(base + "/memory.stat", "inactive_file"));
    }
  }
  if (!v1.empty()) {
    for (const std::string& base :
         {"/sys/fs/cgroup/memory" + (v1 == "/" ? "" : v1), std::string("/sys/fs/cgroup/memory")}) {
      if (!file_number(base + "/memory.limit_in_bytes")) continue;
      take(file_number(base + "/memory.limit_in_bytes"),
           file_number(base + "/memory.usage_in_bytes").value_or(0),
           stat_value(base + "/memory.stat", "total_inactive_file"));
      break;
    }
  }
  return left;
}

// What an address-space limit (ulimit -v) leaves: it counts every mapping, so the process's own
// (its libraries, its thread stacks) is taken off.
std::uint64_t address_space_left() {
  rlimit r{};
  if (::getrlimit(RLIMIT_AS, &r) != 0 || r.rlim_cur == RLIM_INFINITY) return kNoLimit;
  const std::uint64_t used = proc_kb("/proc/self/status", "VmSize").value_or(0);
  return r.rlim_cur > used ? r.rlim_cur - used : 0;
}

}  // namespace

std::string bytes_text(std::uint64_t bytes) {
  static const char* kUnits[] = {"KiB", "MiB", "GiB", "TiB", "PiB"};
  if (bytes < 1024) return std::to_string(bytes) + " bytes";
  double v = static_cast<double>(bytes) / 1024;
  int u = 0;
  while (v >= 1024 && u < 4) {
    v /= 1024;
    ++u;
  }
  char text[32];
  std::snprintf(text, sizeof text, v < 10 ? "%.1f %s" : "%.0f %s", v, kUnits[u]);
  return text;
}

// ZFS's cache (the ARC) gives memory back under pressure, down to its minimum, but MemAvailable
// does not count it: on a ZFS machine whose ARC holds half the memory, runs that fit would be
// refused. Its shrinkable part, from the kstats of the module, where it is loaded.
std::uint64_t zfs_arc_shrinkable() {
  std::ifstream in("/proc/spl/kstat/zfs/arcstats");
  std::string name;
  std::uint64_t type = 0, value = 0, size = 0, minimum = 0;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream f(line);
    if (!(f >> name >> type >> value)) continue;
    if (name == "size") size = value;
    if (name == "c_min") minimum = value;
  }
  return size > minimum ? size - minimum : 0;
}

std::optional<AvailableMemory> available_memory() {
  const std::optional<std::uint64_t> ram = proc_kb("/proc/meminfo", "MemAvailable");
  if (!ram) return std::nullopt;
  const std::uint64_t arc = zfs_arc_shrinkable();
  const std::uint64_t swap = proc_kb("/proc/meminfo", "SwapFree").value_or(0);
  AvailableMemory m;
  m.without_swap = *ram + arc;
  m.most = m.without_swap + swap;
  m.said_by = "MemAvailable " + bytes_text(*ram) +
              (arc > 0 ? ", ZFS's cache " + bytes_text(arc) : std::string()) +
              (swap > 0 ? ", free swap " + bytes_text(swap) : std::string(", no free swap"));
  const std::uint64_t group = cgroup_left();
  if (group < m.most) {
    m.most = group;
    m.said_by = "left by its control group's memory limit";
  }
  const std::uint64_t space = address_space_left();
  if (space < m.most) {
    m.most = space;
    m.said_by = "left by ulimit -v";
  }
  m.without_swap = std::min(m.without_swap, m.most);
  return m;
}

std::optional<SampleLayout> in_core_layout(const std::string& input, const RawOptions& raw) {
  Index3 dims{0, 0, 0};
  ScalarType type = ScalarType::Float32;
  if (const std::optional<FieldSpec> field = parse_field_spec(input)) {
    dims = {field->n, field->n, field->n};
  } else {
    const InputKind kind = input_kind(input);
    if (kind == InputKind::Raw) {
      const RawLayout r = resolve_raw_layout(input, raw);
      dims = r.dims;
      type = r.type;
    } else if (kind == InputKind::Nrrd) {
      const std::optional<NrrdDataLayout> d = nrrd_data_layout(input);
      if (!d) return std::nullopt;
      dims = d->dims;
      type = d->type;
    } else if (kind == InputKind::Dicom) {
      // Its header is a scan of the whole series (GDCM reads every file's), which the read then
      // does again: 12% of a one-shot run of an 81-slice series.
      return std::nullopt;
    } else if (kind == InputKind::Mrc || is_itk_kind(kind)) {
      const VolumeHeader h = read_volume_header(input, raw);
      dims = h.dims;
      type = h.type;
    } else {
      return std::nullopt;
    }
  }
  return SampleLayout{dims, type, checked_volume_bytes(type, dims)};
}

std::uint64_t in_core_bytes(const SampleLayout& layout, const ExtractOptions& extract) {
  if (extract.method == Method::Macet && extract.macet_relax > 0)
    return layout.bytes + layout.bytes / scalar_size(layout.type) * 8;
  return layout.bytes;
}

std::optional<std::uint64_t> in_core_bytes(const std::string& input, const RawOptions& raw,
                                           const ExtractOptions& extract) {
  const std::optional<SampleLayout> layout = in_core_layout(input, raw);
  if (!layout) return std::nullopt;
  return in_core_bytes(*layout, extract);
}

void check_in_core_fits(std::uint64_t need, const AvailableMemory& available,
                        const std::string& input, const Warn& warn) {
  if (need <= available.without_swap) return;
  if (need > available.most) {
    // A budget of a power of two, at most half of what is left, leaves room for the mesh's
    // records and the kernel's page cache of the input.
    std::uint64_t budget = std::uint64_t{64} << 20;
    while (budget * 2 <= available.most / 2) budget *= 2;
    const std::string size = budget >= (std::uint64_t{1} << 30)
                                 ? std::to_string(budget >> 30) + "GiB"
                                 : std::to_string(budget >> 20) + "MiB";
    throw CapacityError(
        input + ": in core, its samples alone take " + bytes_text(need) + ", more than the " +
        bytes_text(available.most) + " of memory this process can have (" + available.said_by +
        "): give --memory SIZE to extract it brick by brick within SIZE (e.g. " + size + ")");
  }
  say_warning(warn, input + ": in core, its samples alone take " + bytes_text(need) +
                        ", more than the " + bytes_text(available.without_swap) +
                        " of memory free without swapping: the run will swap (slow); --memory "
                        "SIZE extracts it brick by brick within SIZE");
}

}  // namespace isotile
