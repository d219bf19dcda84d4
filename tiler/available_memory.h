// How much memory this process can still take, and the in-core run's check against it.
//
// An in-core run holds the whole volume's samples. Where they do not fit, Linux hands out the
// memory anyway (overcommit) and its OOM killer ends the process part-way through the read with
// SIGKILL: no message, exit status 137, after minutes on a large scan. The pipeline asks first.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "core/extract/extract.h"
#include "core/progress.h"
#include "core/volume/volume_io.h"

namespace isotile {

struct AvailableMemory {
  // What the process can take without swapping: the kernel's MemAvailable (and what ZFS's cache
  // would give back, which it does not count), lowered where a
  // control group's limit (memory.max, memory.limit_in_bytes) or an address-space limit
  // (ulimit -v) leaves less.
  std::uint64_t without_swap = 0;
  // And at most, free swap included (an address-space limit caps this too).
  std::uint64_t most = 0;
  // Which figure set `most`, for messages: "MemAvailable 15.2 GiB, no free swap", "the
  // control group's limit", "ulimit -v".
  std::string said_by;
};

// Read from /proc and the control group's files; nullopt where /proc/meminfo cannot be read.
std::optional<AvailableMemory> available_memory();

// "15.2 GiB", "640 MiB", "12 KiB", "300 bytes".
std::string bytes_text(std::uint64_t bytes);

// The samples of `input` as its name, options or header give them, without reading them; nullopt
// where that would cost a read of its own (in_core_bytes()). `bytes` is their size as stored.
struct SampleLayout {
  Index3 dims{0, 0, 0};
  ScalarType type = ScalarType::Float32;
  std::uint64_t bytes = 0;
};
std::optional<SampleLayout> in_core_layout(const std::string& input, const RawOptions& raw);

// The bytes an in-core run of `input` holds at once whatever the surface: its samples (and
// Macet's relaxed copy of them, 8 bytes each, where relax > 0). nullopt where finding them would
// cost a read of its own: a raw volume's size is known from its name or options, a header
// format's from its header (a TIFF stack's: a look at each slice's, 0.01 s for 300 slices), but a
// DICOM series' only from a scan of every file, and an OpenVDB grid's once it is read.
std::optional<std::uint64_t> in_core_bytes(const std::string& input, const RawOptions& raw,
                                           const ExtractOptions& extract);
// The same from the samples' layout.
std::uint64_t in_core_bytes(const SampleLayout& layout, const ExtractOptions& extract);

// Refuses (CapacityError) an in-core run whose `need` bytes exceed what the process can take at
// most, naming both and a --memory budget that fits; warns where it would only fit by swapping.
void check_in_core_fits(std::uint64_t need, const AvailableMemory& available,
                        const std::string& input, const Warn& warn);

}  // namespace isotile
