// HistoPyramid pass 1: the code (case and crossed edges) of every element, two 16-bit codes per
// word; one invocation per word.
layout(std430, binding = 1) writeonly buffer Codes { uint codes[]; };

void main() {
  uint w = invocation();
  uint n = element_count();
  if (2u * w >= n) return;
  uint lo = element_code(element_sample(2u * w));
  uint hi = 2u * w + 1u < n ? element_code(element_sample(2u * w + 1u)) : 0u;
  codes[w] = lo | (hi << 16);
}
