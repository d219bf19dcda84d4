// Shared by every Marching Cubes shader (prepended by gl_program.cpp after "#version 450" and
// the variant's defines: SAMPLE_<TYPE> the samples' stored type (shaders/sample_upload.h),
// SAMPLE_IS_FLOAT when a float holds every value of it, NORMALS when normals are wanted).
//
// Everything that decides a vertex follows core/extract/marching_cubes.cpp exactly: a sample is inside when
// double(value) >= iso; a vertex on the edge from sample s along axis a sits at
// origin + spacing * (s + t e_a) with t = (iso - v(s)) / (v(s + e_a) - v(s)), all in double and
// rounded to float at the end; `precise` forbids fused multiply-adds the CPU does not do, so the
// positions are the CPU's bit for bit where the device's double arithmetic is IEEE.

// The samples as stored (shaders/sample_upload.cpp uploads the volume's bytes unconverted): 8- and
// 16-bit integers packed into 32-bit words (little-endian, as on the host), widened here.
#if defined(SAMPLE_U8) || defined(SAMPLE_I8) || defined(SAMPLE_U16) || defined(SAMPLE_I16)
layout(std430, binding = 0) readonly buffer Samples { uint samples[]; };
#elif defined(SAMPLE_F32)
layout(std430, binding = 0) readonly buffer Samples { float samples[]; };
#elif defined(SAMPLE_I32)
layout(std430, binding = 0) readonly buffer Samples { int samples[]; };
#elif defined(SAMPLE_U32)
layout(std430, binding = 0) readonly buffer Samples { uint samples[]; };
#else
layout(std430, binding = 0) readonly buffer Samples { double samples[]; };
#endif

// Sample i of the uploaded region, widened exactly: to float where a float holds every value of
// the type (SAMPLE_IS_FLOAT), else to double.
#ifdef SAMPLE_IS_FLOAT
float sample_value(uint i) {
#if defined(SAMPLE_U8)
  return float(bitfieldExtract(samples[i >> 2], int(i & 3u) * 8, 8));
#elif defined(SAMPLE_I8)
  return float(bitfieldExtract(int(samples[i >> 2]), int(i & 3u) * 8, 8));
#elif defined(SAMPLE_U16)
  return float(bitfieldExtract(samples[i >> 1], int(i & 1u) * 16, 16));
#elif defined(SAMPLE_I16)
  return float(bitfieldExtract(int(samples[i >> 1]), int(i & 1u) * 16, 16));
#else
  return samples[i];
#endif
}
#else
double sample_value(uint i) { return double(samples[i]); }
#endif

// The case tables of core/extract/marching_cubes_tables.h, uploaded from the same constexpr arrays.
layout(std140, binding = 0) uniform Tables {
  uvec4 tri_table[256];  // per case: bytes 0..14 the edges of its triangles, byte 15 the count
  uvec4 edge_mask[64];   // crossed-edge mask (12 bits) of case c in component c % 4 of c / 4
  ivec4 edge_info[12];   // cell edge e: offset of its lower corner (xyz) and its axis (w)
};

uniform ivec3 u_region_lo;    // global index of the first uploaded sample
uniform ivec3 u_region_dims;  // uploaded samples along x, y, z (x fastest)
uniform ivec3 u_global_dims;  // samples of the whole volume
uniform ivec3 u_box_lo;       // cells extracted: [u_box_lo, u_box_hi), global;
uniform ivec3 u_box_hi;       // their vertices: samples in the closed box [u_box_lo, u_box_hi]
uniform double u_iso;
uniform float u_iso_float;  // the smallest float >= u_iso (core/extract/inside_bits.h's InsideTest)
uniform float u_iso_nearest;  // the float nearest u_iso: what float32 samples hold of it (Macet's ties)
uniform dvec3 u_origin;
uniform dvec3 u_spacing;

// Writes into one component of a double vector through a non-constant index (`v[i] = x`, also
// `+=`, `++`, or as an out argument) do not link on NVIDIA's GLSL compiler ("C9999: can't find
// __setVectorIndex function in stdlib"), which handles int and float vectors; llvmpipe accepts all
// of them. Such writes go through these selects instead: no arithmetic, so exact everywhere.
// Reads through a non-constant index link everywhere. tests/test_glsl_variants.cpp runs glslang
// over every program the code builds and fails on any other such write.
dvec3 with_component(dvec3 v, int i, double x) {
  return dvec3(i == 0 ? x : v.x, i == 1 ? x : v.y, i == 2 ? x : v.z);
}
dvec4 with_component(dvec4 v, int i, double x) {
  return dvec4(i == 0 ? x : v.x, i == 1 ? x : v.y, i == 2 ? x : v.z, i == 3 ? x : v.w);
}
// Element (column c, row r) of a double matrix replaced by x.
dmat3 with_element(dmat3 m, int c, int r, double x) {
  return dmat3(c == 0 ? with_component(m[0], r, x) : m[0], c == 1 ? with_component(m[1], r, x) : m[1],
               c == 2 ? with_component(m[2], r, x) : m[2]);
}

#ifdef STAGE_COMPUTE
layout(local_size_x = 256) in;
// One index per invocation over a 2D grid of groups (the x count is limited to 65535 on some
// devices).
uint invocation() {
  return gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 256u;
}
#endif

// Clamped to the uploaded region: only vertices that are dropped afterwards (the geometry-shader
// path's extra cells beyond a brick) ever ask for samples outside it.
double sample_at(ivec3 g) {
  uvec3 l = uvec3(clamp(g - u_region_lo, ivec3(0), u_region_dims - 1));
  uvec3 d = uvec3(u_region_dims);
  return double(sample_value(l.x + d.x * (l.y + d.y * l.z)));
}

// double(v) >= iso; for float samples the same answer as v >= u_iso_float, which is cheaper.
bool inside(ivec3 g) {
#ifdef SAMPLE_IS_FLOAT
  uvec3 l = uvec3(clamp(g - u_region_lo, ivec3(0), u_region_dims - 1));
  uvec3 d = uvec3(u_region_dims);
  return sample_value(l.x + d.x * (l.y + d.y * l.z)) >= u_iso_float;
#else
  return sample_at(g) >= u_iso;
#endif
}

uint cell_case(ivec3 c) {
  uint cs = 0u;
  for (int k = 0; k < 8; ++k)
    if (inside(c + ivec3(k & 1, (k >> 1) & 1, (k >> 2) & 1))) cs |= 1u << k;
  return cs;
}

uint tri_count(uint cs) { return tri_table[cs].w >> 24; }
uint tri_edge(uint cs, uint i) { return (tri_table[cs][i >> 2] >> (8u * (i & 3u))) & 0xffu; }
uint case_edge_mask(uint cs) { return edge_mask[cs >> 2][cs & 3u]; }

// What a HistoPyramid element's 16-bit code counts: Marching Cubes' crossed edges (bits 8-10) and
// its cell's triangles; with DC_CODES, Dual Contouring's vertices (bits 11-13) and quads (one per
// bit 8-10; dc_common.glsl). The pyramid passes are the same for both.
#ifdef DC_CODES
uint hp_vertex_count(uint code) { return (code >> 11) & 7u; }
uint hp_face_count(uint code) { return uint(bitCount((code >> 8) & 7u)); }
#else
uint hp_vertex_count(uint code) { return uint(bitCount(code >> 8)); }
uint hp_face_count(uint code) { return tri_count(code & 0xffu); }
#endif

// Elements: the samples of the closed box, numbered x fastest. Element e's code holds the case of
// the cell whose lower corner it is (bits 0-7; 0 outside the cell box) and its crossed edges
// (bits 8-10, axis a at bit 8 + a): the edges from it to its +x, +y, +z neighbours that lie in
// the volume. Its vertices are numbered in key order, lin(s) * 3 + a.
ivec3 domain_dims() { return u_box_hi - u_box_lo + 1; }
uint element_count() {
  ivec3 d = domain_dims();
  return uint(d.x) * uint(d.y) * uint(d.z);
}
ivec3 element_sample(uint e) {
  uvec3 d = uvec3(domain_dims());
  return u_box_lo + ivec3(e % d.x, (e / d.x) % d.y, e / (d.x * d.y));
}
uint element_index(ivec3 s) {
  uvec3 l = uvec3(s - u_box_lo);
  uvec3 d = uvec3(domain_dims());
  return l.x + d.x * (l.y + d.y * l.z);
}
uint element_code(ivec3 s) {
  if (all(lessThan(s, u_box_hi))) {
    // A cell's lower corner: its three edges are cell edges 0, 4, 8 (all inside the volume).
    uint cs = cell_case(s);
    uint bits = ((cs ^ (cs >> 1)) & 1u) | (((cs ^ (cs >> 2)) & 1u) << 1) |
                (((cs ^ (cs >> 4)) & 1u) << 2);
    return cs | (bits << 8);
  }
  bool in0 = inside(s);
  uint bits = 0u;
  for (int a = 0; a < 3; ++a) {
    ivec3 t = s;
    t[a] += 1;
    if (t[a] < u_global_dims[a] && inside(t) != in0) bits |= 1u << a;
  }
  return bits << 8;
}

#ifdef NORMALS
// Central differences in world units, one-sided only at the border of the whole volume (never at
// a brick's border): core/extract/marching_cubes.cpp's gradient().
dvec3 gradient(ivec3 p) {
  dvec3 g;
  for (int a = 0; a < 3; ++a) {
    ivec3 lo = p, hi = p;
    if (p[a] > 0) lo[a] -= 1;
    if (p[a] + 1 < u_global_dims[a]) hi[a] += 1;
    precise double h = double(hi[a] - lo[a]) * u_spacing[a];
    precise double d = h > 0.0 ? (sample_at(hi) - sample_at(lo)) / h : 0.0;
    g = with_component(g, a, d);
  }
  return g;
}
#endif

// Position (and unit normal, outward, when NORMALS) of the vertex on edge (s, axis).
void edge_vertex(ivec3 s, int axis, out vec3 pos, out vec3 nrm) {
  ivec3 s1 = s;
  s1[axis] += 1;
  double v0 = sample_at(s), v1 = sample_at(s1);
  precise double t = (u_iso - v0) / (v1 - v0);
  for (int c = 0; c < 3; ++c) {
    precise double g = double(s[c]);
    if (c == axis) g += t;
    precise double w = u_origin[c] + u_spacing[c] * g;
    pos[c] = float(w);
  }
  nrm = vec3(0.0);
#ifdef NORMALS
  dvec3 g0 = gradient(s), g1 = gradient(s1);
  precise dvec3 n = -(g0 + t * (g1 - g0));
  precise double len2 = n.x * n.x + n.y * n.y + n.z * n.z;
  double inv = len2 > 0.0 ? 1.0 / sqrt_rn(len2) : 0.0;
  nrm = vec3(n * inv);
#endif
}
