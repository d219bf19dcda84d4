#!/bin/sh
# Out-of-core simplification against simplifying the whole mesh in core, on one volume: for each
# budget, `isotile extract --memory B --simplify R` (one process: extraction, simplification,
# writing), and for reference `isotile extract --simplify R` in core. Every result is measured
# against the unsimplified extraction with `isotile quality --reference` (two-way sampled
# distance, in the mesh's units: voxels for these volumes).
#
#   tests/benchmarks/bench_simplify_tiled.sh [ISOTILE] [INPUT] [ISO] [RATIO] [BUDGETS...]
#   defaults: build/tiler/isotile ../shared/data/bonsai_256x256x256_uint8.raw.gz 49.5 0.1
#             32MiB 64MiB 128MiB 256MiB
#
# Prints one row per run: wall seconds and peak RSS (GNU time), bricks, triangles, radius ratio
# min and mean, distance mean and max.
set -eu
ISOTILE=${1:-build/tiler/isotile}
INPUT=${2:-../shared/data/bonsai_256x256x256_uint8.raw.gz}
ISO=${3:-49.5}
RATIO=${4:-0.1}
[ $# -gt 4 ] && shift 4 || set --
BUDGETS=${*:-32MiB 64MiB 128MiB 256MiB}
if [ ! -e "$INPUT" ] && [ "${INPUT#field:}" = "$INPUT" ]; then
  echo "bench_simplify_tiled: no $INPUT" >&2
  exit 0
fi
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT INT TERM

"$ISOTILE" -q extract "$INPUT" --iso "$ISO" --method macet -o "$OUT/ref.ply"

row() {  # name extra-args...
  name=$1
  shift
  /usr/bin/time -f "%e %M" -o "$OUT/time" \
    "$ISOTILE" -q extract "$INPUT" --iso "$ISO" --method macet --simplify "$RATIO" \
    -o "$OUT/out.ply" --stats "$OUT/stats.json" "$@"
  "$ISOTILE" quality "$OUT/out.ply" --reference "$OUT/ref.ply" --json > "$OUT/q.json"
  python3 - "$name" "$OUT/time" "$OUT/stats.json" "$OUT/q.json" <<'EOF'
import json, sys
name, tfile, sfile, qfile = sys.argv[1:]
secs, kib = open(tfile).read().split()
s = json.load(open(sfile)); q = json.load(open(qfile))
print(f"| {name} | {float(secs):.2f} | {int(kib) / 1024:.0f} | {s['bricks']} | {q['triangles']} | "
      f"{q['radius_ratio_min']:.3f} | {q['radius_ratio_mean']:.3f} | {q['hausdorff_mean']:.3f} | "
      f"{q['hausdorff_max']:.2f} |")
EOF
}

echo "| run | wall s | peak RSS MB | bricks | triangles | min | mean | distance mean | distance max |"
echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"
row "in core"
for b in $BUDGETS; do
  row "--memory $b" --memory "$b"
done
