// Deterministic fuzzing of the file readers, for every build and CI. Each fuzz target
// (fuzz_targets.h) first reads its seeds (fuzz_seeds.h): the valid ones must read, the others must
// be rejected. Then come thousands of inputs drawn from std::mt19937 with a fixed seed: mutations
// of the seeds (bit flips, interesting bytes, truncations, insertions, duplicated chunks, header
// numbers and keywords swapped, binary counts overwritten, splices, other variants) for the mesh,
// raw and NRRD readers, and random grids written by OpenVDB for the VDB reader (byte mutations
// crash OpenVDB itself; see below). A reader must only ever return or throw isotile::Error; any
// other exception or an invariant violation fails the test and saves the input as
// <temp>/isotile_fuzz_failure_<target>_<input>.bin. A crash leaves it in
// <temp>/isotile_fuzz_<pid>/.
//
// Environment: ISOTILE_FUZZ_ITERATIONS=N sets the number of inputs per target; ISOTILE_FUZZ_SEED=S
// draws another sequence (the default is what CI runs); ISOTILE_FUZZ_VDB_BYTES=N adds N byte
// mutations of the VDB seeds, for runs by hand.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <new>
#include <random>
#include <string>
#include <string_view>
#include <typeinfo>
#include <utility>
#include <vector>

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(leak_sanitizer)
#define ISOTILE_HAVE_LSAN 1
#endif
#endif
#if !defined(ISOTILE_HAVE_LSAN) && defined(__SANITIZE_ADDRESS__)
#define ISOTILE_HAVE_LSAN 1
#endif
#if ISOTILE_HAVE_LSAN
#include <sanitizer/lsan_interface.h>
#endif

#include "tests/fuzz/fuzz_seeds.h"
#include "tests/fuzz/fuzz_targets.h"

// An allocation cap for the readers, in the spirit of libFuzzer's -malloc_limit_mb: while
// g_allocation_cap is set, operator new refuses larger requests with std::bad_alloc (which the
// readers report as isotile::Error) instead of letting a few corrupt bytes commit gigabytes.
// Replacing operator new (and, to keep the pairs matched under ASan, operator delete) is standard
// C++; the replacements also serve the shared libraries (OpenVDB, TBB). Calls to malloc (teem,
// zlib) are not capped.
namespace {
constexpr std::size_t kAllocationCap = std::size_t{32} << 20;
std::atomic<std::size_t> g_allocation_cap{0};  // 0: no cap
std::atomic<std::uint64_t> g_refused_allocations{0};

void* allocate(std::size_t n) noexcept {
  const std::size_t cap = g_allocation_cap.load(std::memory_order_relaxed);
  if (cap != 0 && n > cap) {
    g_refused_allocations.fetch_add(1, std::memory_order_relaxed);
    return nullptr;
  }
  return std::malloc(n == 0 ? 1 : n);
}
}  // namespace

void* operator new(std::size_t n) {
  if (void* p = allocate(n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  if (void* p = allocate(n)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  return allocate(n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  return allocate(n);
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"  // free() is right: allocate() mallocs
#endif
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete[](void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete(void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// Under AddressSanitizer and ThreadSanitizer, let malloc return null for impossible sizes as glibc
// does, rather than abort: teem allocates whatever a (fuzzed) NRRD header asks for and copes with a
// null result.
extern "C" __attribute__((used)) const char* __asan_default_options() {
  return "allocator_may_return_null=1";
}
extern "C" __attribute__((used)) const char* __tsan_default_options() {
  return "allocator_may_return_null=1";
}

// ITK 5.2's NIfTI writer (write_itk, which writes the seeds) leaks the two file names niftiio
// makes. ITK's TIFF reader leaks its scanline buffer when a page's rows cannot be read, and
// MetaIO a buffer of MetaImage::ReadStream on some malformed headers (both throw before freeing;
// the error itself reaches the user).
extern "C" __attribute__((used)) const char* __lsan_default_suppressions() {
  return "leak:nifti_makeimgname\nleak:nifti_makehdrname\nleak:TIFFImageIO::ReadGenericImage\n"
         "leak:MetaImage::ReadStream\n";
}

namespace isotile::fuzz {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;
using Target = int (*)(const std::uint8_t*, std::size_t);

std::uint64_t env_number(const char* name, std::uint64_t fallback) {
  const char* v = std::getenv(name);
  if (!v || !*v) return fallback;
  return std::strtoull(v, nullptr, 10);
}

// Tables of values worth trying, kept compact.
// clang-format off

// Header numbers: limits of the integer types, overflows, signs, non-numbers.
constexpr std::string_view kNumbers[] = {
    "0", "1", "-1", "2", "3", "127", "255", "256", "65535", "65536", "2147483647", "2147483648",
    "-2147483648", "4294967295", "4294967296", "9223372036854775807", "9223372036854775808",
    "-9223372036854775808", "18446744073709551615", "18446744073709551616",
    "99999999999999999999999", "1e308", "1e-320", "3.4028236e38", "-0", "nan", "inf", "-inf",
    "0x10", "+5", ""};

constexpr std::uint8_t kBytes[] = {0, 1, 0x7f, 0x80, 0xff, '-', '+', '9', '0', ' ', '\n', '\r',
                                   '#', '/', '.', 'e', 0xfe, 0x40};

constexpr std::uint64_t kWords[] = {
    0, 1, 0x7f, 0x80, 0xff, 0x7fff, 0x8000, 0xffff, 0x10000, 0x7fffffff, 0x80000000, 0xffffffff,
    0x100000000, 0x7fffffffffffffff, 0x8000000000000000, 0xffffffffffffffff};

// Keywords of the formats, swapped in for a word of the input.
constexpr std::string_view kMeshWords[] = {
    "ply", "format", "ascii", "binary_little_endian", "binary_big_endian", "element", "vertex",
    "face", "property", "list", "uchar", "char", "short", "ushort", "int", "uint", "float",
    "double", "int8", "uint32", "x", "nx", "vertex_indices", "end_header", "comment", "v", "vn",
    "vt", "f", "OFF", "NOFF", "COFF", "solid", "endsolid", "facet", "normal", "outer", "loop",
    "endloop", "endfacet"};
constexpr std::string_view kImageWords[] = {
    "NDims = ", "DimSize = ", "ElementType = ", "MET_FLOAT", "MET_SHORT", "MET_UCHAR",
    "ElementDataFile = ", "LOCAL", "CompressedData = True", "HeaderSize = ", "BinaryDataByteOrderMSB = True",
    "ElementNumberOfChannels = ", "TransformMatrix = ", "n+1", "ni1", "MAP "};
constexpr std::string_view kNrrdWords[] = {
    "NRRD0004", "NRRD0005", "type:", "dimension:", "sizes:", "spacings:", "encoding:", "raw",
    "gzip", "bzip2", "ascii", "hex", "endian:", "big", "little", "data file:", "LIST", "space:",
    "space dimension:", "space directions:", "space origin:", "none", "kinds:", "domain", "space",
    "line skip:", "byte skip:", "-1", "float", "double", "uchar", "short", "int", "long long",
    "block", "block size:", "content:", "(nan,nan,nan)", "(1e400,0,0)", "data.bin"};

// clang-format on

class Mutator {
 public:
  Mutator(std::uint32_t seed, const std::vector<Seed>& seeds, bool selector,
          std::vector<std::string_view> words)
      : rng_(seed), seeds_(seeds), selector_(selector), words_(std::move(words)) {}

  Bytes next() {
    Bytes b = seeds_[below(seeds_.size())].bytes;
    // Mostly one or two edits, sometimes many.
    const int edits = 1 + (below(2) ? 0 : static_cast<int>(below(2) ? below(3) : below(12)));
    for (int i = 0; i < edits; ++i) mutate(b);
    return b;
  }

 private:
  // Plain modulo rather than a distribution: the same inputs with every standard library.
  std::size_t below(std::size_t n) { return n == 0 ? 0 : rng_() % n; }
  // Positions near the start, where the headers are, half of the time.
  std::size_t position(const Bytes& b) {
    if (b.empty()) return 0;
    return below(2) ? below(std::min<std::size_t>(b.size(), 256)) : below(b.size());
  }

  void mutate(Bytes& b) {
    switch (below(13)) {
      case 0:  // bit flip
        if (!b.empty()) b[position(b)] ^= static_cast<std::uint8_t>(1u << below(8));
        break;
      case 1:  // interesting byte
        if (!b.empty()) b[position(b)] = kBytes[below(std::size(kBytes))];
        break;
      case 2:  // random byte
        if (!b.empty()) b[position(b)] = static_cast<std::uint8_t>(below(256));
        break;
      case 3:  // truncation
        b.resize(below(b.size() + 1));
        break;
      case 4: {  // insertion of random or interesting bytes
        const std::size_t at = below(b.size() + 1);
        Bytes ins(1 + below(8));
        for (auto& x : ins)
          x = below(2) ? kBytes[below(std::size(kBytes))] : static_cast<std::uint8_t>(below(256));
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), ins.begin(), ins.end());
        break;
      }
      case 5: {  // a chunk duplicated elsewhere
        if (b.empty()) break;
        const std::size_t from = below(b.size());
        const std::size_t len = 1 + below(std::min<std::size_t>(b.size() - from, 256));
        const Bytes chunk(b.begin() + static_cast<std::ptrdiff_t>(from),
                          b.begin() + static_cast<std::ptrdiff_t>(from + len));
        const std::size_t at = below(b.size() + 1);
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), chunk.begin(), chunk.end());
        break;
      }
      case 6: {  // a chunk erased
        if (b.empty()) break;
        const std::size_t from = position(b);
        const std::size_t len = 1 + below(std::min<std::size_t>(b.size() - from, 64));
        b.erase(b.begin() + static_cast<std::ptrdiff_t>(from),
                b.begin() + static_cast<std::ptrdiff_t>(from + len));
        break;
      }
      case 7:
      case 8:
        edit_number(b);
        break;
      case 9: {  // a binary integer, either byte order
        const std::size_t width = std::size_t{1} << below(4);
        if (b.size() < width) break;
        std::size_t at = position(b);
        at = std::min(at, b.size() - width);
        if (below(2)) at &= ~(width - 1);
        std::uint64_t v = kWords[below(std::size(kWords))];
        if (below(4) == 0) v = ~v + 1;  // negated
        const bool big = below(2);
        for (std::size_t k = 0; k < width; ++k)
          b[at + k] = static_cast<std::uint8_t>(v >> (8 * (big ? width - 1 - k : k)));
        break;
      }
      case 10: {  // splice: a prefix of this input, a suffix of another seed
        const Bytes& other = seeds_[below(seeds_.size())].bytes;
        b.resize(below(b.size() + 1));
        const std::size_t from = below(other.size() + 1);
        b.insert(b.end(), other.begin() + static_cast<std::ptrdiff_t>(from), other.end());
        break;
      }
      case 11:
        replace_word(b);
        break;
      case 12:  // another variant: file name or reader options
        if (selector_ && !b.empty()) b[0] = static_cast<std::uint8_t>(below(256));
        break;
    }
  }

  // Replaces a run of decimal digits (with its sign and fraction) by an interesting number.
  void edit_number(Bytes& b) {
    std::vector<std::pair<std::size_t, std::size_t>> runs;  // begin, end
    for (std::size_t i = 0; i < b.size() && runs.size() < 4096;) {
      if (b[i] >= '0' && b[i] <= '9') {
        std::size_t s = i;
        if (s > 0 && b[s - 1] == '-') --s;
        while (i < b.size() && ((b[i] >= '0' && b[i] <= '9') || b[i] == '.' || b[i] == 'e')) ++i;
        runs.emplace_back(s, i);
      } else {
        ++i;
      }
    }
    if (runs.empty()) return;
    // Favour the first numbers: counts and sizes live in the headers.
    const auto [s, e] =
        runs[below(2) ? below(std::min<std::size_t>(runs.size(), 16)) : below(runs.size())];
    const std::string_view n = kNumbers[below(std::size(kNumbers))];
    b.erase(b.begin() + static_cast<std::ptrdiff_t>(s), b.begin() + static_cast<std::ptrdiff_t>(e));
    b.insert(b.begin() + static_cast<std::ptrdiff_t>(s), n.begin(), n.end());
  }

  // Replaces a word (letters, digits, '_', ':') by a keyword of the format.
  void replace_word(Bytes& b) {
    if (b.empty() || words_.empty()) return;
    auto word_char = [](std::uint8_t c) { return std::isalnum(c) || c == '_' || c == ':'; };
    std::size_t i = position(b);
    while (i < b.size() && !word_char(b[i])) ++i;
    if (i == b.size()) return;
    std::size_t s = i;
    while (s > 0 && word_char(b[s - 1])) --s;
    while (i < b.size() && word_char(b[i])) ++i;
    const std::string_view w = words_[below(words_.size())];
    b.erase(b.begin() + static_cast<std::ptrdiff_t>(s), b.begin() + static_cast<std::ptrdiff_t>(i));
    b.insert(b.begin() + static_cast<std::ptrdiff_t>(s), w.begin(), w.end());
  }

  std::mt19937 rng_;
  const std::vector<Seed>& seeds_;
  bool selector_;
  std::vector<std::string_view> words_;
};

std::string hex_prefix(const Bytes& b) {
  std::string s;
  char buf[4];
  for (std::size_t i = 0; i < b.size() && i < 48; ++i) {
    std::snprintf(buf, sizeof buf, "%02x", b[i]);
    s += buf;
  }
  if (b.size() > 48) s += "...";
  return s;
}

fs::path save_input(const std::string& kind, const char* name, const std::string& label,
                    const Bytes& input) {
  const fs::path path = fs::temp_directory_path() /
                        ("isotile_fuzz_" + kind + "_" + std::string(name) + "_" + label + ".bin");
  if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(input.data(), 1, input.size(), f);
    std::fclose(f);
  }
  return path;
}

struct TargetInfo {
  const char* name;
  Target target;
  bool selector;                        // whether the first byte picks a variant
  std::vector<std::string_view> words;  // keywords of the format
  // Whether the reader may ask for more than kAllocationCap at once. Only OpenVDB does: it sizes
  // buffers from counts in the file without checking them against the file's size.
  bool large_allocations = false;
  // Whether to keep LeakSanitizer out of the reader's allocations: teem leaks its decompressor
  // state whenever a gzip or bzip2 NRRD turns out corrupt.
  bool ignore_leaks = false;
};

// Keeps LeakSanitizer, where present, from reporting what this thread allocates meanwhile.
class LeaksIgnored {
 public:
  explicit LeaksIgnored(bool on) : on_(on) {
#if ISOTILE_HAVE_LSAN
    if (on_) __lsan_disable();
#endif
  }
  ~LeaksIgnored() {
#if ISOTILE_HAVE_LSAN
    if (on_) __lsan_enable();
#endif
  }
  LeaksIgnored(const LeaksIgnored&) = delete;
  LeaksIgnored& operator=(const LeaksIgnored&) = delete;

 private:
  [[maybe_unused]] bool on_;
};

// Runs one input. Anything but a return or isotile::Error is a failure, saved for reproduction;
// so is an allocation over the cap where the target promises none. Returns the target's result,
// or -1 on failure.
int run_one(const TargetInfo& t, const Bytes& input, const std::string& label) {
  std::string problem;
  const std::uint64_t refused_before = g_refused_allocations.load();
  const auto start = std::chrono::steady_clock::now();
  int result = -1;
  try {
    const LeaksIgnored leaks_ignored(t.ignore_leaks);
    result = t.target(input.data(), input.size());
  } catch (const InvariantViolation& e) {
    problem = std::string("invariant violated: ") + e.what();
  } catch (const std::exception& e) {
    problem = std::string("escaped ") + typeid(e).name() + ": " + e.what();
  } catch (...) {
    problem = "escaped an exception that is not a std::exception";
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (problem.empty() && !t.large_allocations && g_refused_allocations.load() != refused_before)
    problem = "asked for more than " + std::to_string(kAllocationCap >> 20) + " MiB at once";
  if (!problem.empty()) {
    const fs::path saved = save_input("failure", t.name, label, input);
    ADD_FAILURE() << t.name << " input " << label << " (" << input.size() << " bytes, saved as "
                  << saved.string() << ", starts " << hex_prefix(input) << "): " << problem;
    return -1;
  }
  // Reported, not failed: timings vary too much between machines and sanitizers.
  if (seconds > 1) {
    const fs::path saved = save_input("slow", t.name, label, input);
    std::printf("note: %s input %s took %.2f s (saved as %s)\n", t.name, label.c_str(), seconds,
                saved.c_str());
  }
  return result;
}

// Runs the seeds (the valid ones must read, the others must be rejected), then `count` inputs
// from `next`, and prints what happened.
void replay(const TargetInfo& t, const std::vector<Seed>& seeds,
            const std::function<Bytes(std::uint64_t)>& next, std::uint64_t count) {
  ASSERT_FALSE(seeds.empty());
  const auto start = std::chrono::steady_clock::now();
  const std::uint64_t refused_before = g_refused_allocations.load();
  g_allocation_cap = kAllocationCap;
  for (const Seed& s : seeds) {
    const int r = run_one(t, s.bytes, s.name);
    EXPECT_EQ(r, s.readable ? 0 : 1)
        << t.name << " seed " << s.name << (s.readable ? " was rejected" : " was accepted");
  }
  std::uint64_t accepted = 0, rejected = 0, failed = 0, done = 0;
  for (; done < count && failed < 5; ++done) {
    const int r = run_one(t, next(done), std::to_string(done));
    if (r == 0) ++accepted;
    if (r == 1) ++rejected;
    if (r < 0) ++failed;
  }
  g_allocation_cap = 0;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "%s: %zu seeds, %llu inputs: %llu read, %llu rejected, %llu failed; %llu allocations "
      "over %zu MiB refused; %.2f s\n",
      t.name, seeds.size(), static_cast<unsigned long long>(done),
      static_cast<unsigned long long>(accepted), static_cast<unsigned long long>(rejected),
      static_cast<unsigned long long>(failed),
      static_cast<unsigned long long>(g_refused_allocations.load() - refused_before),
      kAllocationCap >> 20, seconds);
  // Inputs that all fail to parse would test little beyond the first checks.
  if (failed == 0 && count >= 500) {
    EXPECT_GT(accepted, count / 50) << t.name;
  }
}

// Mutations of the seeds.
void replay_mutations(const TargetInfo& t, const std::vector<Seed>& seeds, std::uint32_t seed,
                      std::uint64_t count) {
  Mutator mutator(seed, seeds, t.selector, t.words);
  replay(
      t, seeds, [&](std::uint64_t) { return mutator.next(); }, count);
}

std::uint32_t rng_seed(std::uint32_t per_target) {
  return static_cast<std::uint32_t>(env_number("ISOTILE_FUZZ_SEED", 20240601)) ^ per_target;
}

std::uint64_t iterations(std::uint64_t fallback) {
  return env_number("ISOTILE_FUZZ_ITERATIONS", fallback);
}

TEST(FuzzReplay, MeshReader) {
  replay_mutations({"mesh", fuzz_mesh, true, {std::begin(kMeshWords), std::end(kMeshWords)}},
                   mesh_seeds(), rng_seed(1), iterations(20000));
}

TEST(FuzzReplay, RawReader) {
  replay_mutations({"raw", fuzz_raw, true, {}}, raw_seeds(), rng_seed(2), iterations(10000));
}

TEST(FuzzReplay, NrrdReader) {
  // teem may legitimately inflate a small gzip'd file into a large volume.
  replay_mutations({"nrrd",
                    fuzz_nrrd,
                    true,
                    {std::begin(kNrrdWords), std::end(kNrrdWords)},
                    /*large_allocations=*/true,
                    /*ignore_leaks=*/true},
                   nrrd_seeds(), rng_seed(3), iterations(15000));
}

// NIfTI and MetaImage reach ITK only past isotile's header checks; MRC is isotile's own reader.
TEST(FuzzReplay, ImageReaders) {
  replay_mutations({"image",
                    fuzz_image,
                    true,
                    {std::begin(kImageWords), std::end(kImageWords)},
                    /*large_allocations=*/false,
                    /*ignore_leaks=*/false},
                   image_seeds(), rng_seed(5), iterations(4000));
}

// Random grids written by OpenVDB rather than mutated bytes: OpenVDB 10 does not survive mutated
// files (a heap overflow in io::unzipFromStream, loops and allocations sized by unchecked 32-bit
// counts; see docs/development.md). ISOTILE_FUZZ_VDB_BYTES=N adds N byte mutations of the seeds,
// for runs by hand.
TEST(FuzzReplay, VdbReader) {
  const TargetInfo t{"vdb", fuzz_vdb, false, {}, /*large_allocations=*/true};
  const std::uint32_t seed = rng_seed(4);
  replay(
      t, vdb_seeds(),
      [&](std::uint64_t i) { return random_vdb_seed(seed + static_cast<std::uint32_t>(i)).bytes; },
      iterations(1000));
  if (const std::uint64_t n = env_number("ISOTILE_FUZZ_VDB_BYTES", 0)) {
    replay_mutations(t, vdb_seeds(), seed, n);
  }
}

}  // namespace
}  // namespace isotile::fuzz
