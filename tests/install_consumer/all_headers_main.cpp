// Appended to an #include of every installed header: calls into the tiler (and the GL backends
// where they were built) so that linking those libraries is checked too.
#include <cstdio>

int main() {
  // 128^3 samples within 1 MiB per brick: several bricks.
  const isotile::BrickPlan plan = isotile::plan_bricks({128, 128, 128}, {.memory = 1 << 20});
  std::printf("bricks %lld\n", static_cast<long long>(plan.total()));
#ifdef HAVE_GL
  isotile::gl::register_gl_backends();
  std::printf("gl backends registered\n");
#endif
  return plan.total() > 1 ? 0 : 1;
}
