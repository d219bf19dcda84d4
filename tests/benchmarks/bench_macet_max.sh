#!/usr/bin/env bash
# Macet --quality max, one build against another, side by side: bonsai and engine at 49.5 (from
# ../shared/data) and noisy volumes like MRI scans (tests/benchmarks/noisy_volume.py). For each
# volume and build: the median of 3 fresh `isotile extract` processes' seconds.extract, the ratio
# old / new, and the quality (--stats: min, 0.1% quantile, mean radius ratio) and intersecting
# pairs (--check-intersections) of one run.
#
# usage: tests/benchmarks/bench_macet_max.sh OLD_ISOTILE NEW_ISOTILE [THREADS]
#   e.g. tests/benchmarks/bench_macet_max.sh ../main/build/tiler/isotile build/tiler/isotile
set -euo pipefail
old=${1:?usage: bench_macet_max.sh OLD_ISOTILE NEW_ISOTILE [THREADS]}
new=${2:?usage: bench_macet_max.sh OLD_ISOTILE NEW_ISOTILE [THREADS]}
threads=${3:-2}
here=$(cd "$(dirname "$0")" && pwd)
data=${ISOTILE_SHARED_DATA:-$here/../../../shared/data}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

volumes=()
for f in bonsai_256x256x256_uint8.raw.gz engine_256x256x128_uint8.raw.gz; do
  if [[ -f $data/$f ]]; then volumes+=("$data/$f|49.5|"); else echo "skipping $f (not in $data)" >&2; fi
done
for spec in "48 3 3 2 1.0 128" "48 2 2 2 1.0 156" "64 5 3 2 0.6 110"; do
  read -r n seed passes radius detail iso <<<"$spec"
  f=$tmp/noisy_${n}_${seed}.raw
  python3 "$here/noisy_volume.py" "$f" "$n" "$seed" "$passes" "$radius" "$detail"
  volumes+=("$f|$iso|--dims $n,$n,$n --type uint8")
done

run() {  # binary volume iso extra -> prints seconds.extract; stats in $tmp/stats.json
  local bin=$1 vol=$2 iso=$3 extra=$4
  # shellcheck disable=SC2086
  "$bin" --threads "$threads" extract "$vol" $extra --iso "$iso" --method macet --quality max \
    -o "$tmp/out.ply" --stats "$tmp/stats.json" "${@:5}" >/dev/null 2>&1
  python3 -c "import json; print(json.load(open('$tmp/stats.json'))['seconds']['extract'])"
}
quality() {
  python3 -c "
import json; d = json.load(open('$tmp/stats.json'))
print('min %.4f q0.1%% %.4f mean %.4f pairs %d' % (d['radius_ratio_min'], d['radius_ratio_q001'],
      d['radius_ratio_mean'], d['self_intersections']))"
}
median() { printf '%s\n' "$@" | sort -g | sed -n 2p; }

printf '%-32s %10s %10s %7s  %s\n' volume old_s new_s ratio "quality old | new"
for spec in "${volumes[@]}"; do
  IFS='|' read -r vol iso extra <<<"$spec"
  t_old=() t_new=()
  for _ in 1 2 3; do  # interleaved, so that load on the machine hits both alike
    t_old+=("$(run "$old" "$vol" "$iso" "$extra")")
    t_new+=("$(run "$new" "$vol" "$iso" "$extra")")
  done
  run "$old" "$vol" "$iso" "$extra" --check-intersections >/dev/null
  q_old=$(quality)
  run "$new" "$vol" "$iso" "$extra" --check-intersections >/dev/null
  q_new=$(quality)
  m_old=$(median "${t_old[@]}") m_new=$(median "${t_new[@]}")
  printf '%-32s %10.3f %10.3f %7.2f  %s | %s\n' "$(basename "$vol")@$iso" "$m_old" "$m_new" \
    "$(python3 -c "print($m_old / $m_new)")" "$q_old" "$q_new"
done
