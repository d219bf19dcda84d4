#!/usr/bin/env bash
# The GPU checks of the GL paths, as one prepared run on a GPU machine (docs/gl.md, "Checking on
# a GPU"). Built and packed here, run there:
#
#   cmake -S . -B build-gpu -G Ninja -DCMAKE_BUILD_TYPE=Release -DISOTILE_ITK=OFF \
#       -DISOTILE_MESHLAB=OFF -DISOTILE_MPI=OFF -DISOTILE_BUILD_BENCHMARKS=ON
#   cmake --build build-gpu --target isotile test_gl test_gl_macet test_gl_dc gl_double_check \
#       bench_backends
#   ../shared/tools/gpu_bundle.sh build-gpu/tiler/isotile build-gpu/tests/test_gl \
#       build-gpu/tests/test_gl_macet build-gpu/tests/test_gl_dc build-gpu/tests/gl_double_check \
#       build-gpu/tests/benchmarks/bench_backends
#   then, on the GPU machine, with .gpu/ carried along:
#   source .gpu/env.sh && bash tests/gpu/run_gpu_checks.sh [--quick]
#
# Prints one line per check, "gpu-check: NAME: pass|FAIL (...)", and a summary; exit 1 when any
# check fails. --quick: the bricked runs on gyroid 192 in 16 MiB bricks (a smoke run, also on llvmpipe).
set -uo pipefail
size=1024 memory=8GiB
[ "${1:-}" = --quick ] && size=192 memory=16MiB
out=${TMPDIR:-/tmp}/isotile-gpu-checks
rm -rf "$out" && mkdir -p "$out"
failed=0
report() {  # NAME STATUS DETAIL
  if [ "$2" = 0 ]; then echo "gpu-check: $1: pass ${3:-}"; else echo "gpu-check: $1: FAIL ${3:-}"; failed=$((failed + 1)); fi
}
nvidia-smi -L 2>/dev/null | head -1
isotile gl-info || report gl-info 1 "(no OpenGL context)"

# 1. The GL test programs: every one must pass (the positions' tolerance off llvmpipe: docs/gl.md).
for t in test_gl test_gl_macet test_gl_dc; do
  "$t" --gtest_brief=1 >"$out/$t.log" 2>&1
  rc=$?
  tail -n 3 "$out/$t.log"
  grep -m 5 -E 'Failure|error' "$out/$t.log"
  report "$t" $rc
done

# 2. Bricked runs at 16 threads on both GL paths: exit 0 (no crash at exit, glibc's heap checks
# on), and the CPU's file byte for byte.
isotile --threads 16 extract "field:gyroid:$size" -q --memory "$memory" --backend cpu -o "$out/cpu.ply"
report "bricked cpu gyroid $size" $?
for b in hp gs; do
  MALLOC_CHECK_=3 isotile --threads 16 extract "field:gyroid:$size" -q --memory "$memory" \
    --backend "$b" -o "$out/$b.ply" --stats "$out/$b.json" 2>"$out/$b.err"
  rc=$?
  cat "$out/$b.err"
  report "bricked $b gyroid $size exits 0" $rc "(exit $rc)"
  cmp -s "$out/cpu.ply" "$out/$b.ply"
  report "bricked $b gyroid $size same file as cpu" $?
  rm -f "$out/$b.ply"
done
rm -f "$out/cpu.ply"

# 3. Every method on the GL paths through the CLI (auto stays on the CPU; the GL paths named).
for m in "--method mc --normals" "--method macet" "--method macet --quality max" "--method dc" \
         "--method dc --dc-solver qef --dc-hermite eno"; do
  isotile extract field:marschner-lobb:96 -q $m --backend cpu -o "$out/m-cpu.ply"
  for b in hp gs; do
    isotile extract field:marschner-lobb:96 -q $m --backend "$b" -o "$out/m-$b.ply" \
      --stats "$out/m-$b.json"
    report "cli $b $m runs" $?
  done
done

# 4. The device's double arithmetic against the CPU's.
gl_double_check 4000000
report "double / and sqrt as the CPU" $?

# 5. Every backend's mesh against the CPU's, and their times (16 threads, warm, median of 5).
bench_backends --threads 16 | tee "$out/bench_backends.txt"
report bench_backends $?
if grep -qw NO "$out/bench_backends.txt"; then report "bench_backends: a row says same mesh NO" 1; fi

echo "gpu-check: $failed failed"
[ "$failed" = 0 ]
