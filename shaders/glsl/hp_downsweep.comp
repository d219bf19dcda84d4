// HistoPyramid pass 2b: the vertex offset of every node of levels 1..L-1 (the number of vertices
// before its first element), top-down, up to three levels per dispatch: a node's offset is its
// parent's plus its left siblings' counts. Lets a triangle corner find its vertex index from one
// offset and at most seven codes instead of summing left siblings on every level.
// A workgroup covers 256 consecutive nodes of level u_bottom, one per invocation, and their 32
// parents and 4 grandparents up to level u_bottom + u_steps - 1; the offsets of the level above
// those come from an earlier dispatch (or, for the top node, a clear to zero), the levels in
// between pass theirs down through shared memory. ONE_LEVEL_PER_PASS: one level, without shared
// memory and barriers (which cost a software rasteriser more than the passes they save;
// hp_pyramid.cpp).
// FACE_OFFSETS: the faces' offsets as well (after the vertices'), for the per-element output
// passes.
uniform int u_bottom;  // lowest level written, >= 1
#ifdef ONE_LEVEL_PER_PASS
const int u_steps = 1;
#else
uniform int u_steps;  // levels written: 1, 2 or 3
#endif
#ifdef FACE_OFFSETS
#define Offsets uvec2
Offsets counts_at(uint q) { return pyramid[q]; }
Offsets offset_at(uint q) { return uvec2(vertex_offset[q], vertex_offset[face_offset_at(q)]); }
void store_offset(uint q, Offsets o) {
  vertex_offset[q] = o.x;
  vertex_offset[face_offset_at(q)] = o.y;
}
#else
#define Offsets uint
Offsets counts_at(uint q) { return pyramid[q].x; }
Offsets offset_at(uint q) { return vertex_offset[q]; }
void store_offset(uint q, Offsets o) { vertex_offset[q] = o; }
#endif
shared Offsets s_offset[64];  // one level's offsets in this group; the level below's in the other half

void main() {
  // No early return: every invocation reaches every barrier (invocations past the last node
  // write nothing).
  uint g = invocation() >> 8;
  uint t = gl_LocalInvocationIndex;
  for (int j = u_steps - 1; j >= 0; --j) {
    int l = u_bottom + j;
    uint n = 256u >> (3 * j);  // this group's nodes of level l: 256, 32 or 4
    uint p = n * g + t;
    Offsets sum = Offsets(0u);
    if (t < n && p < u_level_count[l]) {
      sum = j == u_steps - 1 ? offset_at(u_level_offset[l + 1] + (p >> 3))
                             : s_offset[32u * uint((j + 1) & 1) + (t >> 3)];
      for (uint q = p & ~7u; q < p; ++q) sum += counts_at(u_level_offset[l] + q);
      store_offset(u_level_offset[l] + p, sum);
    }
#ifndef ONE_LEVEL_PER_PASS
    if (j > 0) {
      // This level's offsets are in place before the level below reads them, and the level
      // below's are written after the last read of the half they go to.
      if (t < n) s_offset[32u * uint(j & 1) + t] = sum;
      memoryBarrierShared();
      barrier();
    }
#endif
  }
}
