#!/bin/sh
# Out-of-core tiler benchmark: in-core against bricked (--memory) extraction of the same volumes,
# run one after the other, each in its own process so that peak RSS is the run's own.
#
#   tests/benchmarks/bench_tiler.sh [ISOTILE] [N_SMALL] [N_LARGE] [BUDGET]
#   defaults: build/tiler/isotile 512 1024 256MiB
#
# Prints, per run: wall seconds, throughput in million cells per second, peak RSS (GNU time,
# Debian package `time`), triangles; then each bricked run's throughput relative to the in-core
# run of the same size. No --stats: its measures (quality, distances) are not extraction work.
set -eu
ISOTILE=${1:-build/tiler/isotile}
SMALL=${2:-512}
LARGE=${3:-1024}
BUDGET=${4:-256MiB}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT INT TERM

run() {  # name N extra-args...
  name=$1
  n=$2
  shift 2
  /usr/bin/time -f "%e %M" -o "$OUT/$name.time" \
    "$ISOTILE" -q extract "field:gyroid:$n" -o "$OUT/$name.ply" "$@"
  tris=$(head -c 400 "$OUT/$name.ply" | sed -n 's/^element face //p')
  rm -f "$OUT/$name.ply"
  read -r secs kib < "$OUT/$name.time"
  echo "$name $n $secs $kib $tris" >> "$OUT/results"
}

run incore_small "$SMALL"
run tiled_small "$SMALL" --memory "$BUDGET"
run incore_large "$LARGE"
run tiled_large "$LARGE" --memory "$BUDGET"

awk -v budget="$BUDGET" '
  { secs[$1] = $3; n = $2 - 1; rate[$1] = n * n * n / $3 / 1e6
    printf "%-13s N=%-5d %8.2f s %8.1f Mcells/s %7.0f MB peak RSS %10d triangles\n",
           $1, $2, $3, rate[$1], $4 / 1024, $5 }
  END { printf "budget %s: bricked/in-core throughput %.2f (small), %.2f (large)\n", budget,
               rate["tiled_small"] / rate["incore_small"], rate["tiled_large"] / rate["incore_large"] }
' "$OUT/results"
