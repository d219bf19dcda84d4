// The OpenGL Marching Cubes extractors (geometry-shader and HistoPyramid paths) and their
// installation into core's backend table.
//
// Both give exactly the CPU's mesh (core/extract/marching_cubes.h): the same vertices in key order
// (lin(s) * 3 + axis), the same triangles cell by cell in table order, positions computed with
// the CPU's double-precision formula. Volumes larger than the device's memory (or its largest
// storage-buffer binding) are split into slabs along z, each extracted on its own; their seams
// are keyed by global edge, so the result equals the whole-volume extraction.
#pragma once

#include <cstdint>
#include <string>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/volume/volume.h"
#include "shaders/stage_clock.h"

namespace isotile::gl {

struct McOptions {
  double iso = 0.0;
  bool normals = false;
  // Brick mode, global cells; empty: every cell of the view. Same contract as
  // MarchingCubesOptions::cells (core/extract/marching_cubes.h): the triangles of these cells, the
  // vertices of the crossed edges owned by samples of the closed box, the view holding the cells
  // plus marching_cubes_halo() samples.
  Box3 cells{};
  // Device memory to plan bricks for, in bytes. 0: half of what the driver reports free
  // (GL_NVX_gpu_memory_info, GL_ATI_meminfo), or 1 GiB when it does not say.
  std::uint64_t memory = 0;
  // For tests: at most this many cells along z per brick (0: as memory allows).
  std::int64_t max_brick_cells_z = 0;
  // Geometry-shader path, for tests: bytes of the transform-feedback capture buffer (0: sized from
  // memory, at most 2 GiB per binding). A small value forces the overflow-and-resume passes.
  std::uint64_t capture_bytes = 0;
  Progress* progress = nullptr;  // Stage::Extract per slab; Cancelled between slabs
};

struct McStats {
  int bricks = 0;
  int capture_passes = 0;  // geometry-shader draws, resumed ones included
  // Slabs whose samples were uploaded while the slab before was being counted (HistoPyramid) or
  // drawn (geometry shader).
  int early_uploads = 0;
  // HistoPyramid: dispatches of the vertex and face passes (one each per slab where they fit
  // their buffers).
  int output_chunks = 0;
  // HistoPyramid: dispatches building the count pyramid and its vertex offsets (hp_pyramid.h).
  int pyramid_passes = 0;
  // Seconds per stage summed over the slabs, from GL timer queries (stage_clock.h; no glFinish),
  // and the bytes of samples uploaded.
  GlTimes times;
};

// Throw InputError when no OpenGL 4.5 context can be created, CapacityError when the mesh needs
// more than 2^32 - 1 vertices or one x-y slab of the volume does not fit the device.
Mesh mc_geometry_shader(const VolumeView& view, const McOptions& options, McStats* stats = nullptr);
Mesh mc_histopyramid(const VolumeView& view, const McOptions& options, McStats* stats = nullptr);

// The on-disk program cache (program_cache.h) as `isotile gl-info` shows it: its folder (empty
// when neither XDG_CACHE_HOME nor HOME is set) and whether this process uses it, with the reason
// when not. Creates the context (throws like device()).
struct ProgramCacheState {
  std::string folder;
  bool enabled = false;
  std::string off_because;
};
ProgramCacheState program_cache_state();

// Fills the GeometryShader and HistoPyramid entries of core's backend table
// (core/extract/extract.h). Call once at startup, before extract().
void register_gl_backends();

}  // namespace isotile::gl
