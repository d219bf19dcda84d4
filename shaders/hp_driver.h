// The HistoPyramid driver that every method runs on (mc_histopyramid.cpp describes the pyramid):
// Marching Cubes and Macet (mc_histopyramid.cpp, macet_gl.cpp) and Dual Contouring on both paths
// (dc_histopyramid.cpp; its geometry-shader path emits the faces from the same pyramid).
//
// Per slab of cells along z: the samples are uploaded, the method's own passes run, one 16-bit
// code per element is classified, the count pyramid and its vertex offsets are built, the totals
// are read back, then the vertex and face passes write the outputs (one invocation per output
// descending to its element, or one per element: hp_pyramid.h's HpOutput), read back in chunks
// that fit one storage-buffer binding. Slab i + 1's elements start with slab
// i's top layer, whose vertices slab i drops, so a vertex's index is the running base plus its
// slab-local index in either slab. The method plugs in its element box, its shaders and defines,
// its uniforms and buffers, and the kind of face it emits.
#pragma once

#include <glad/gl.h>

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/volume/volume.h"
#include "gl_backends.h"
#include "gl_program.h"
#include "hp_pyramid.h"

namespace isotile::gl {

enum class HpFaces {
  Triangles,         // 3 vertex indices per face (Marching Cubes, Macet)
  Quads,             // 4 per face, into Mesh::quads (Dual Contouring, --quads)
  QuadsAsTriangles,  // 6 per face: the two triangles of a split quad (Dual Contouring)
};

struct HpMethod {
  int halo = 0;  // samples around a slab's cells that its region must hold
  // Device bytes per region sample besides the samples themselves (codes, pyramid, the method's
  // buffers), and the largest single buffer's bytes per region sample besides the samples.
  double bytes_per_sample = 0, largest_per_sample = 0;
  // The global elements of a slab of cells (global): one code, and a pyramid leaf, each.
  std::function<Box3(const Box3& cells)> elements;
  // Appended to the samples' defines, per pass: the pyramid's (reduce, down-sweep, prefix), the
  // classification's, the vertex pass's and the face pass's.
  std::string pyramid_defines, classify_defines, vertex_defines, face_defines;
  std::string_view classify_file, vertex_file, face_file;  // shaders/glsl/
  HpFaces faces = HpFaces::Triangles;
  bool normals = false;
  bool patch_maps = false;  // a word per element at storage binding 6 (Dual Contouring)
  // The face pass reads every vertex position of the slab (binding 4), so the vertex pass writes
  // them in one buffer; a slab whose vertices overflow a binding is halved (Dual Contouring).
  bool positions_on_device = false;
  // Binds the method's tables (once per run).
  std::function<void()> bind_tables;
  // Sets a program's uniforms beyond GridUniforms (may be empty): the slab's element box given.
  std::function<void(GLuint, const Box3& elements)> uniforms;
  // Runs once a slab's samples are uploaded and bound (binding 0) and the tables bound; leaves
  // what the vertex shaders read bound and returns its buffers, kept until the slab is done.
  std::function<std::vector<Buffer>(const Samples&, const GridUniforms&, const std::string&)>
      prepare;
  // Emits the faces from a geometry shader instead of the face pass (Dual Contouring's
  // geometry-shader path): with the slab's buffers bound as for the face pass, the `n_faces`
  // faces of the `elements` elements into `out`, `defines` being the face pass's; returns the
  // number of draws.
  std::function<int(const std::string& defines, const std::function<void(GLuint)>& uniforms,
                    const Pyramid& pyr, std::uint64_t elements, std::uint64_t n_faces,
                    std::uint32_t* out)>
      gs_faces;
};

struct HpRun {
  Box3 cells;  // global cells to extract, non-empty, inside the view's cells
  double iso = 0;
  std::uint64_t memory = 0;            // device bytes to plan slabs for (0: from the driver)
  std::int64_t max_brick_cells_z = 0;  // for tests: a cap on a slab's cells along z
  Progress* progress = nullptr;        // Stage::Extract per slab; Cancelled between slabs
};

Mesh histopyramid_driver(const VolumeView& view, const HpRun& run, const HpMethod& method,
                         McStats* stats);

}  // namespace isotile::gl
