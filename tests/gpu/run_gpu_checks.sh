#!/usr/bin/env bash
# The GPU checks of the GL paths, as one prepared run on a GPU machine (docs/gl.md, "Checking on
# a GPU"). Built and packed here, run there:
#
#   cmake -S . -B build-gpu -G Ninja -DCMAKE_BUILD_TYPE=Release -DISOTILE_ITK=OFF \
#       -DISOTILE_MESHLAB=OFF -DISOTILE_MPI=OFF -DISOTILE_BUILD_BENCHMARKS=ON
#   cmake --build build-gpu --target isotile test_gl test_gl_macet test_gl_dc gl_double_check \
#       bench_backends bench_hp_layouts
#   ../shared/tools/gpu_bundle.sh build-gpu/tiler/isotile build-gpu/tests/test_gl \
#       build-gpu/tests/test_gl_macet build-gpu/tests/test_gl_dc build-gpu/tests/gl_double_check \
#       build-gpu/tests/benchmarks/bench_backends build-gpu/tests/benchmarks/bench_hp_layouts
#   mkdir -p gpu-data && cp ../shared/data/bonsai_256x256x256_uint8.raw.gz \
#       ../shared/data/engine_256x256x128_uint8.raw.gz gpu-data/   (the shared data does not
#       travel to the GPU machine; gpu-data/ is an untracked folder of the working tree: do not
#       commit it)
#   then, on the GPU machine, with .gpu/ and gpu-data/ carried along:
#   source .gpu/env.sh && ISOTILE_GPU_DATA=$PWD/gpu-data bash tests/gpu/run_gpu_checks.sh [--quick]
#
# --part=1 runs the correctness checks only (steps 1 to 5), --part=2 the measurements (6 to 8):
# two calls of the lent machine, each within its 600 s, where the whole might not fit one. The
# long steps run under time limits (limit() below), so that one that hangs costs only its own.
# Where $OUT names a folder (the device machine's), the whole output is also written to
# $OUT/gpu-checks.log and the raw logs, tables and stats packed into one archive beside it
# ($OUT/gpu-checks-part-P-files.tar.gz: at most 8 files come back from $OUT).
# Prints one line per check, "gpu-check: NAME: pass|FAIL (...)", and a summary; exit 1 when any
# check fails. Measurements print as "gpu-measure: ..." lines: the read-back's GB/s straight and
# through pinned buffers, the upload's by staging piece size with and without each piece handed
# to the device at once (gl::submit()), whole hp MC calls with and without those hand-offs, the
# pyramid's build at 1, 2 and 3 levels per dispatch and the output
# passes per output against per element (bench_backends' "hpe" columns; issue 36),
# and the data path's targets (issue 35): upload GB/s on gyroid 256/512 and bonsai, out of core
# on gyroid $size and a 4 GiB uint8 volume made from bonsai, the one-shot whole process of
# `extract field:gyroid:512` on hp against cpu with a warm program cache, the context's start-up.
# --quick: the bricked runs on gyroid 192 in 16 MiB bricks and the measurements on gyroid 128
# (a smoke run, also on llvmpipe). The GL program cache goes to a fresh XDG_CACHE_HOME under the
# output folder, so the first GL run is cold and every later one warm.
set -uo pipefail
size=1024 memory=8GiB part=all slow=1
for arg in "$@"; do
  case "$arg" in
    --quick) size=192 memory=16MiB slow=5 ;;  # also a smoke run on llvmpipe: longer limits
    --part=1 | --part=2) part=${arg#--part=} ;;
    *) echo "run_gpu_checks.sh: unknown argument '$arg' (--quick, --part=1, --part=2)" >&2; exit 2 ;;
  esac
done
in_part() { [ "$part" = all ] || [ "$part" = "$1" ]; }
out=${TMPDIR:-/tmp}/isotile-gpu-checks/part-$part
rm -rf "$out" && mkdir -p "$out"
# On the lent machine only what is written under $OUT comes back (at most 8 files), and of the
# output only its tail: the whole output goes to $OUT/gpu-checks.log as it is printed (so a run
# cut short by the time limit still returns what it measured), and the logs, tables and stats of
# $out go into one archive there at the end (python3's tarfile: the machine has python3).
if [ -n "${OUT:-}" ] && [ -d "$OUT" ]; then
  exec > >(tee -a "$OUT/gpu-checks.log") 2>&1
  trap '(cd "$out" && python3 -m tarfile -c "$OUT/gpu-checks-part-$part-files.tar.gz" \
    $(ls -- *.log *.txt *.json 2>/dev/null))' EXIT
fi
export XDG_CACHE_HOME="$out/cache"
data=${ISOTILE_GPU_DATA:-}
failed=0
report() {  # NAME STATUS DETAIL
  if [ "$2" = 0 ]; then echo "gpu-check: $1: pass ${3:-}"; else echo "gpu-check: $1: FAIL ${3:-}"; failed=$((failed + 1)); fi
}
# The long steps run under a time limit, so that one that hangs on a driver costs its limit and
# not the whole call: exit 124 (a failure where it is a check) and a "gpu-timeout:" line.
limit() {  # SECONDS COMMAND...
  local seconds=$(($1 * slow))
  shift
  timeout --kill-after=10 "$seconds" "$@"
  local rc=$?
  [ "$rc" = 124 ] && echo "gpu-timeout: $1 stopped after $seconds s"
  return "$rc"
}
nvidia-smi -L 2>/dev/null | head -1
isotile gl-info || report gl-info 1 "(no OpenGL context)"

# The data path's stages from --stats (seconds.gl).
json_get() {  # FILE EXPR (python3 expression over j)
  python3 -c "import json,sys; j=json.load(open(sys.argv[1])); print($2)" "$1"
}
gl_stages() {  # FILE [bricks]: "[N bricks, upload ]G GB/s, B bytes; stages ms NAME MS, ..."
  local head=
  [ -n "${2:-}" ] && head='"%d bricks, upload " % j["bricks"] + '
  json_get "$1" "$head"'"%.2f GB/s, %d bytes; stages ms " % (j["upload_gbps"], j["upload_bytes"]) + ", ".join("%s %.2f" % (k, 1e3 * v) for k, v in j["seconds"]["gl"].items())'
}

# Part 1: correctness, steps 1 to 5.
if in_part 1; then
# 1. The GL test programs: every one must pass (the positions' tolerance off llvmpipe: docs/gl.md).
for t in test_gl test_gl_macet test_gl_dc; do
  limit 200 "$t" --gtest_brief=1 >"$out/$t.log" 2>&1
  rc=$?
  tail -n 3 "$out/$t.log"
  grep -m 5 -E 'Failure|error|gpu-timeout' "$out/$t.log"
  report "$t" $rc
done
# 2. Bricked runs at 16 threads on both GL paths: exit 0 (no crash at exit, glibc's heap checks
# on), and the CPU's file byte for byte.
limit 150 isotile --threads 16 extract "field:gyroid:$size" -q --memory "$memory" --backend cpu \
  -o "$out/cpu.ply"
report "bricked cpu gyroid $size" $?
for b in hp gs; do
  MALLOC_CHECK_=3 limit 150 isotile --threads 16 extract "field:gyroid:$size" -q --memory "$memory" \
    --backend "$b" -o "$out/$b.ply" --stats "$out/$b.json" 2>"$out/$b.err"
  rc=$?
  cat "$out/$b.err"
  report "bricked $b gyroid $size exits 0" $rc "(exit $rc)"
  cmp -s "$out/cpu.ply" "$out/$b.ply"
  report "bricked $b gyroid $size same file as cpu" $?
  rm -f "$out/$b.ply"
done
rm -f "$out/cpu.ply"
# Out of core: the uploads of the bricks summed (seconds.gl over the bricks).
for b in hp gs; do
  [ -f "$out/$b.json" ] && echo "gpu-measure: out of core gyroid $size $b: $(gl_stages "$out/$b.json" bricks)"
done

# 3. Every method on the GL paths through the CLI (auto stays on the CPU; the GL paths named): the
# CPU's file byte for byte.
for m in "--method mc --normals" "--method macet" "--method macet --quality max" "--method dc" \
         "--method dc --dc-solver particle" "--method dc --dc-solver qef --dc-hermite eno"; do
  isotile extract field:marschner-lobb:96 -q $m --backend cpu -o "$out/m-cpu.ply"
  for b in hp gs; do
    isotile extract field:marschner-lobb:96 -q $m --backend "$b" -o "$out/m-$b.ply" \
      --stats "$out/m-$b.json"
    report "cli $b $m runs" $?
    cmp -s "$out/m-cpu.ply" "$out/m-$b.ply"
    report "cli $b $m same file as cpu" $?
  done
done
rm -f "$out"/m-*.ply

# 4. The device's double arithmetic against the CPU's, and the shaders' sqrt_rn().
gl_double_check 4000000
report "double /, precise a * b + c and sqrt_rn as the CPU" $?

# 5. The HistoPyramid extractions again with one pyramid level per dispatch (a software device's
# passes, without shared memory and barriers; the GPU's default is three), and with per-element
# output passes (the default descends the pyramid once per output): shaders/hp_pyramid.h. Last
# in part 1: the modes that are not the default, after the known failures' checks above.
hp_tests='Gl/*/Hp:GlHistoPyramid.*'
for variant in "ISOTILE_HP_LEVELS_PER_PASS=1 one-level one pyramid level per pass" \
               "ISOTILE_HP_OUTPUT=scatter per-element per-element output passes"; do
  read -r setting tag what <<<"$variant"
  for t in test_gl test_gl_macet test_gl_dc; do
    (export "$setting" && limit 120 "$t" --gtest_brief=1 --gtest_filter="$hp_tests") \
      >"$out/$t-$tag.log" 2>&1
    rc=$?
    grep -m 5 -E 'Failure|error|gpu-timeout' "$out/$t-$tag.log"
    report "$t hp, $what" $rc
  done
done

fi

# Part 2: the measurements, steps 6 to 8.
if in_part 2; then
# 6. Every backend's mesh against the CPU's, and their times (16 threads, warm, median of 5), with
# the GL stages from timer queries, upload GB/s and triangles/s; gyroid 512 unless --quick. "hpe"
# is the HistoPyramid with per-element output passes: whether it beats "hp" decides the default.
# The calls run on the context's thread, which keeps the context current (shaders/gl_context.h):
# on the H200 taking it again cost each call 150-230 ms when every call took it, which cut the
# table short at 360 s in Macet's rows (docs/benchmarks.md); the table printed first says what a
# take costs now and then (the context per take and release), and step 8 the one-shot.
big=--gyroid512 bench_repeat=5
# --quick: one run per cell of the table (at five, llvmpipe took more than 600 s on gyroid 256)
[ "$size" = 192 ] && big= bench_repeat=1
limit 360 bench_backends --threads 16 --repeat $bench_repeat $big \
  ${data:+--data "$data"} | tee "$out/bench_backends.txt"
report bench_backends "${PIPESTATUS[0]}"
# What taking the context costs, and which EGL call costs it (gl.md, "On the NVIDIA H200").
grep -A7 '^context per take' "$out/bench_backends.txt" | sed 's/^/gpu-measure: /'
if grep -qw NO "$out/bench_backends.txt"; then report "bench_backends: a row says same mesh NO" 1; fi
# The read-back on its own (shaders/read_back.h): straight through GL against the pinned buffers.
grep -A4 '^read-back GB/s' "$out/bench_backends.txt" | sed 's/^/gpu-measure: /'
# The upload on its own (shaders/sample_upload.h): staging pieces of 2, 8 and 32 MiB, each handed
# to the device as it is filled (gl::submit()), and 32 MiB left to the next wait as before; then
# whole hp MC calls with and without those submissions: which piece size, and whether they pay.
grep -A4 '^upload GB/s' "$out/bench_backends.txt" | sed 's/^/gpu-measure: /'
grep -A8 '^hp MC whole calls' "$out/bench_backends.txt" | sed 's/^/gpu-measure: /'
# The pyramid's layouts and the compact output design (docs/gl.md, "A second output design"): it
# stops with FAILED when a layout's counts or outputs differ from the CPU's or the linear's.
repeat=5
[ "$size" = 192 ] && repeat=1  # --quick: llvmpipe's texture descents take minutes
limit 150 bench_hp_layouts --threads 16 --repeat $repeat ${data:+--data "$data"} |
  tee "$out/bench_hp_layouts.txt"
report bench_hp_layouts "${PIPESTATUS[0]}"
# The pyramid built with 1, 2 and 3 levels per dispatch (shaders/hp_pyramid.h): which to keep.
grep -A4 '^production build' "$out/bench_hp_layouts.txt" | sed 's/^/gpu-measure: /'

# 7. The data path (issue 35). Upload GB/s and the stages, a run with a warm program cache each:
# gyroid 256 and 512 float32, bonsai uint8 (from $ISOTILE_GPU_DATA).
inputs="field:gyroid:256 field:gyroid:512"
[ "$size" = 192 ] && inputs="field:gyroid:128"
if [ -n "$data" ] && [ -f "$data/bonsai_256x256x256_uint8.raw.gz" ]; then
  inputs="$inputs $data/bonsai_256x256x256_uint8.raw.gz"
else
  echo "gpu-measure: bonsai skipped (set ISOTILE_GPU_DATA to a folder holding bonsai_256x256x256_uint8.raw.gz)"
fi
for in in $inputs; do
  iso=; case "$in" in *bonsai*) iso="--iso 49.5" ;; esac
  for run in warmup measured; do
    isotile --threads 16 extract "$in" $iso -q --backend hp -o "$out/d.ply" --stats "$out/d.json"
    rc=$?
  done
  report "hp $in runs" $rc
  [ $rc = 0 ] && echo "gpu-measure: upload $(basename "$in"): $(gl_stages "$out/d.json"); program cache $(json_get "$out/d.json" 'j["gl_program_cache"]["state"]')"
done
rm -f "$out/d.ply"
# Out of core: a 4 GiB uint8 volume (bonsai repeated 8x8x4, made here from $ISOTILE_GPU_DATA), in
# bricks within 2 GiB: the bricks' uploads summed (seconds.gl over the bricks); the gyroid's are
# step 2's.
big_u8="$out/bonsai-tiled_2048x2048x1024_uint8.raw"
if [ "$size" != 192 ] && [ -n "$data" ] && [ -f "$data/bonsai_256x256x256_uint8.raw.gz" ]; then
  # Each z-slice of bonsai repeated 8 times along x and y, the whole 4 times along z (no NumPy).
  python3 - "$data/bonsai_256x256x256_uint8.raw.gz" "$big_u8" <<'PY'
import gzip, sys
v = gzip.open(sys.argv[1]).read()
n = 256
slices = []
for z in range(n):
    rows = [v[(z * n + y) * n:(z * n + y + 1) * n] * 8 for y in range(n)]
    slices.append(b"".join(rows) * 8)
with open(sys.argv[2], "wb") as f:
    for _ in range(4):
        for s in slices:
            f.write(s)
PY
  for b in cpu hp; do
    t0=$(date +%s.%N)
    limit 150 isotile --threads 16 extract "$big_u8" --iso 49.5 -q --memory 2GiB --backend "$b" \
      -o "$out/big-$b.ply" --stats "$out/big-$b.json"
    rc=$?
    t1=$(date +%s.%N)
    report "out of core 4 GiB uint8 $b runs" $rc
    [ $rc = 0 ] && [ "$b" = hp ] && echo "gpu-measure: out of core 4 GiB uint8 hp: $(gl_stages "$out/big-$b.json" bricks)"
    echo "gpu-measure: out of core 4 GiB uint8 $b: whole process $(python3 -c "print(f'{$t1 - $t0:.2f}')") s, $(json_get "$out/big-$b.json" '"%d triangles" % j["triangles"]')"
  done
  cmp -s "$out/big-cpu.ply" "$out/big-hp.ply"
  report "out of core 4 GiB uint8 hp same file as cpu" $?
  rm -f "$big_u8" "$out"/big-*.ply
else
  echo "gpu-measure: out of core 4 GiB uint8 skipped (--quick, or no bonsai in ISOTILE_GPU_DATA)"
fi

# 8. One-shot whole process, warm program cache: `extract field:gyroid:512` on hp against cpu,
# 5 processes each, interleaved, median wall seconds; and the context's start-up.
one=field:gyroid:512
[ "$size" = 192 ] && one=field:gyroid:128
isotile --threads 16 extract $one -q --backend hp -o "$out/o.ply"  # the cache warm
wall() {  # BACKEND: wall seconds of one process
  local t0 t1
  t0=$(date +%s.%N)
  isotile --threads 16 extract $one -q --backend "$1" -o "$out/o-$1.ply" || return 1
  t1=$(date +%s.%N)
  python3 -c "print(f'{$t1 - $t0:.3f}')"
}
cpu_t=() hp_t=()
for i in 1 2 3 4 5; do cpu_t+=("$(wall cpu)") hp_t+=("$(wall hp)"); done
median() { printf '%s\n' "$@" | sort -g | sed -n 3p; }
echo "gpu-measure: one-shot $one whole process (median of 5): cpu $(median "${cpu_t[@]}") s [${cpu_t[*]}], hp $(median "${hp_t[@]}") s [${hp_t[*]}]"
cmp -s "$out/o-cpu.ply" "$out/o-hp.ply"
report "one-shot $one hp same file as cpu" $?
isotile --threads 16 extract $one -q --backend hp -o "$out/o.ply" --stats "$out/o.json"
echo "gpu-measure: one-shot $one hp: context start-up $(json_get "$out/o.json" '"%.3f s" % j["seconds"]["gl"]["context"]'), extract $(json_get "$out/o.json" '"%.3f s" % j["seconds"]["extract"]'), total $(json_get "$out/o.json" '"%.3f s" % j["seconds"]["total"]'), program cache $(json_get "$out/o.json" 'j["gl_program_cache"]["state"]'); $(gl_stages "$out/o.json")"
rm -f "$out"/o*.ply
# The same with the program cache cold: a fresh XDG_CACHE_HOME (Mesa's shader cache follows it
# too, and so may the NVIDIA driver's own: then the driver's cache is cold as well).
XDG_CACHE_HOME="$out/cold-cache" isotile --threads 16 extract $one -q --backend hp -o "$out/o.ply" --stats "$out/o.json"
echo "gpu-measure: one-shot $one hp, isotile's program cache cold: total $(json_get "$out/o.json" '"%.3f s" % j["seconds"]["total"]'), $(json_get "$out/o.json" 'j["gl_program_cache"]["compiled"]') programs compiled"
rm -f "$out"/o*.ply
fi

echo "gpu-check: $failed failed"
[ "$failed" = 0 ]
