// Small GL helpers shared by the GL extractors: programs built from the embedded GLSL (cached per
// variant), buffers, compute dispatch, the Marching Cubes tables as a uniform buffer, and the
// upload of a volume region. Call only inside a gl::Scope.
#pragma once

#include <glad/gl.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/errors.h"
#include "core/mesh/mesh.h"
#include "core/volume/volume.h"

namespace isotile::gl {

std::string_view embedded_glsl(std::string_view name);  // generated: embedded_shaders.cpp

// Throws isotile::Error naming `where` when GL reports an error.
void check(const char* where);

struct Stage {
  GLenum type;
  std::string_view file;  // a file of shaders/glsl/
};

// `v` as a GLSL double expression of its exact bits (packDouble2x32), for constants handed to the
// shaders: a decimal literal would rest on the driver's parsing of it.
std::string glsl_double(double v);

// The source of one stage exactly as program() compiles it: "#version 450 core", the stage's
// define, `defines`, sqrt_rn.glsl, mc_common.glsl, the included files the stage needs, then its
// file. The stages of `isotile render` (render_*) are "#version 450 core", `defines` and their
// file only. Needs no context (tests/test_glsl_variants.cpp checks every variant with glslang).
std::string stage_source(const Stage& stage, const std::string& defines);

// The key program() caches a program under: its defines and stage files.
std::string program_key(const std::vector<Stage>& stages, const std::string& defines);

// The program of `stages` (sources from stage_source()); with transform-feedback `varyings`
// (interleaved) when given. Built once per (stages, defines) and kept until shutdown() (in
// gl_context.h). Throws Error with the compiler's log.
GLuint program(const std::vector<Stage>& stages, const std::string& defines,
               const std::vector<const char*>& varyings = {});

// The keys of every program built in this process (the GL tests check each against the table of
// program_variants(), gl_variants.h).
std::vector<std::string> built_program_keys();

// Deletes the cached programs, the case tables and the vertex array (shutdown() calls it, with
// the context current).
void release_programs();

// The vertex array without attributes that the geometry-shader paths draw points with.
GLuint empty_vertex_array();

// A GL buffer object owned by this handle.
class Buffer {
 public:
  Buffer() = default;
  // Immutable storage of `bytes` (at least 4), filled from `data` when given.
  explicit Buffer(std::size_t bytes, const void* data = nullptr, GLbitfield flags = 0);
  ~Buffer();
  Buffer(Buffer&& o) noexcept : id_(o.id_), bytes_(o.bytes_) { o.id_ = 0; }
  Buffer& operator=(Buffer&& o) noexcept;
  GLuint id() const { return id_; }
  std::size_t bytes() const { return bytes_; }
  void bind(GLenum target, GLuint index) const;
  // Through pinned buffers when large (read_back.h).
  void read(std::size_t offset, std::size_t bytes, void* out) const;

 private:
  GLuint id_ = 0;
  std::size_t bytes_ = 0;
};

// A buffer of host memory that the device reaches by DMA (client storage: pinned), mapped
// persistently and coherently for the context's life, with a fence for the last device command
// that uses it: the staging of the samples' upload (sample_upload.cpp) and of the mesh's
// read-back (read_back.cpp). Plain data; create() and release() with the context current.
struct MappedBuffer {
  GLuint id = 0;
  std::byte* mapped = nullptr;
  GLsync fence = nullptr;
  std::size_t bytes = 0;

  // Storage of `size` bytes mapped with `access` (GL_MAP_WRITE_BIT or GL_MAP_READ_BIT); throws
  // Error "OpenGL could not map <what>" when the driver cannot.
  void create(std::size_t size, GLbitfield access, const char* what);
  // At least `at_least` bytes: created, or made again larger (after its fence) where smaller.
  // True when it made one.
  bool ensure(std::size_t at_least, GLbitfield access, const char* what);
  // Unmaps and deletes it (and its fence); empty again.
  void release();
  // Fences the commands issued so far (the copy that uses the buffer).
  void fence_commands();
  // Waits until the fenced commands have completed (none: returns at once).
  void wait();
};

// The size of the pinned buffers for a transfer of `need` bytes in pieces of at most `piece`:
// `need` rounded up to a power of two, at least kMinMappedBytes, at most `piece`. The driver pins
// (and llvmpipe zeroes) every byte of such a buffer when it is made: 0.18-0.24 s for the 32 MiB
// of the samples' first staging buffer on this project's 2-core VM, where a 64^3 volume needs 1.
inline constexpr std::size_t kMinMappedBytes = std::size_t{1} << 20;
std::size_t mapped_bytes_for(std::size_t need, std::size_t piece);
// The bytes of `buffers` (0 for those not made).
std::size_t bytes_held(std::span<const MappedBuffer> buffers);

// Wall seconds create() has taken in this process (the driver pins and maps the memory; once per
// buffer, as the buffers are kept), for --stats (seconds.gl.pinned).
double mapped_buffer_seconds();

// Runs the current compute program (local size 256 in x) over n invocations; the shaders compute
// their index with invocation() (mc_common.glsl), as a 2D grid of groups past the x limit.
void dispatch(std::uint64_t n);

// Hands the commands issued so far to the device (glFlush) where the CPU goes on to work of its
// own: filling the next staging buffer, loading the next programs, sizing the mesh's arrays. A
// driver may keep commands in its queue until something waits for them, and the device would sit
// idle meanwhile (llvmpipe does: stage_clock.cpp). Does not wait. set_submit_early(false) leaves
// the commands to the next wait, as before these calls existed (benchmarks measure the
// difference); submissions() counts the calls that flushed, for tests.
void submit();
void set_submit_early(bool on);
int submissions();

// After a transform-feedback draw from element `first` captured `written` of the `generated`
// primitives (each tagged with its element by `element_of`): the primitives to keep and the
// element to draw from next (`end` when everything fit). On an overflow the last captured
// element may be cut short, so its primitives are dropped and the draw resumes at it.
struct CaptureCut {
  std::uint64_t keep = 0, resume = 0;
};
template <class ElementOf>
CaptureCut cut_capture(std::uint64_t first, std::uint64_t end, std::uint64_t written,
                       std::uint64_t generated, ElementOf element_of) {
  CaptureCut c{written, end};
  if (written < generated) {
    const std::uint64_t last = element_of(written - 1);
    while (c.keep > 0 && element_of(c.keep - 1) == last) --c.keep;
    c.resume = last;
    if (c.keep == 0 && c.resume == first)
      throw Error("transform feedback captured no element (its primitives exceed the buffer)");
  }
  return c;
}

// A method's case tables as the std140 uniform block `Tables` of mc_common.glsl, bound at uniform
// binding 0, uploaded once per context from core's own tables: Marching Cubes'
// (core/extract/marching_cubes_tables.h) or Macet's (core/extract/macet_table.h: MC's polygons
// and crossed edges, other triangulations).
enum class CaseTable { MarchingCubes, Macet };
void bind_case_tables(CaseTable which = CaseTable::MarchingCubes);

// A slab's samples on the device (sample_upload.h).
struct Samples;

// Sets the uniforms every MC shader reads (mc_common.glsl) on `prog`.
struct GridUniforms {
  Box3 region;  // global samples uploaded
  Box3 cells;   // global cells extracted
  Index3 global_dims;
  double iso;
  Vec3d origin, spacing;
};
void set_grid_uniforms(GLuint prog, const GridUniforms& u);

}  // namespace isotile::gl

namespace isotile::gl {

// Bytes of device memory to plan for: `requested` when non-zero, else half the free memory the
// driver reports, else 1 GiB.
std::uint64_t memory_budget(std::uint64_t requested);

// The global cells to extract: `cells` clipped to the view's cells, or all of them when empty.
Box3 cells_to_extract(const VolumeView& view, const Box3& cells);

// Splits `cells` into slabs along z (full x and y) so that one slab's buffers fit:
// `bytes_per_sample` device bytes per uploaded sample, no single buffer above the largest
// storage-buffer binding (`largest_per_sample` bytes per sample for the largest), `halo` extra
// sample planes on each side. `max_cells_z` (> 0) caps the thickness. Throws CapacityError when
// even a one-cell slab does not fit.
std::vector<Box3> plan_slabs(const VolumeView& view, const Box3& cells, double bytes_per_sample,
                             double largest_per_sample, int halo, std::uint64_t budget,
                             std::int64_t max_cells_z);

// plan_slabs() for a driver that uploads the next slab's samples (`sample_bytes` each) while it
// works on this one, its own buffers taking `method_bytes` per sample: with several slabs, two
// slabs' samples share the budget (planned again so), one slab holds only its own.
std::vector<Box3> plan_overlapped_slabs(const VolumeView& view, const Box3& cells,
                                        double sample_bytes, double method_bytes,
                                        double largest_per_sample, int halo, std::uint64_t budget,
                                        std::int64_t max_cells_z);

// The global samples a slab of cells needs: its cells' corners and the far ends of the edges of
// its closed box, plus `halo` samples around (gradients), clipped to the view.
Box3 slab_region(const VolumeView& view, const Box3& cells, int halo);

// What a method whose vertices sit on MC's crossed edges (Marching Cubes itself, Macet) brings to
// the two Marching Cubes paths: the classification, the count pyramid, the capture and the weld
// depend on the inside bits only, so they serve both; the method adds its table, its vertex
// (selected in the shaders by `defines`) and passes that run before the output passes.
struct EdgeMethod {
  int halo = 0;                   // samples around a slab's cells that its region must hold
  double bytes_per_sample = 0;    // device bytes per region sample for `prepare`'s buffers
  double largest_per_sample = 0;  // of those, the largest single buffer's
  std::string defines;            // appended to every program's defines
  CaseTable table = CaseTable::MarchingCubes;
  // Runs once a slab's samples are uploaded and bound (binding 0) and the tables bound; leaves
  // what the vertex shaders read bound and returns the buffers, kept until the slab is done.
  std::function<std::vector<Buffer>(const Samples&, const GridUniforms&, const std::string&)>
      prepare;
};

// The drivers of mc_histopyramid.cpp and mc_geometry_shader.cpp for any EdgeMethod.
struct McOptions;
struct McStats;
Mesh histopyramid_mesh(const VolumeView& view, const McOptions& o, McStats* stats,
                       const EdgeMethod& method);
Mesh geometry_shader_mesh(const VolumeView& view, const McOptions& o, McStats* stats,
                          const EdgeMethod& method);

}  // namespace isotile::gl
