#!/bin/sh
# In-core stages of one CLI run: reading a raw file, writing binary PLY and the --stats measures
# (quality and topology), as rates, for one binary or two side by side (before/after).
#
#   tests/benchmarks/bench_incore.sh VOLUME ISO REPS ISOTILE_A [ISOTILE_B]
#   e.g. tests/benchmarks/bench_incore.sh /big/bonsai-tiled_2048x2048x1024_uint8.raw 49.5 2 \
#          old/isotile build/tiler/isotile
#
# The runs alternate (A, B, A, B, ...) so that both see the same load. Output goes to $OUT_DIR
# (default /dev/shm, tmpfs: the write rate is then not the disk's) and is deleted after each run;
# only one output exists at a time. Per run it prints read GB/s (sample bytes / seconds.read),
# write GB/s (file bytes / seconds.write), measure Mtri/s (triangles / seconds.measure), peak
# RSS, and the stats' seconds; then the median rate of each binary and B/A ratios. With two
# binaries it also checks that both wrote byte-identical meshes and identical stats (all keys but
# seconds, peak_rss_mb and output): exit status 1 when they differ. Needs python3.
set -eu
if [ $# -lt 4 ]; then
  sed -n 4,5p "$0" >&2
  exit 2
fi
VOLUME=$1
ISO=$2
REPS=$3
shift 3
OUT_DIR=${OUT_DIR:-/dev/shm}
WORK=$(mktemp -d)
MESH="$OUT_DIR/bench_incore_$$.ply"
trap 'rm -rf "$WORK" "$MESH"' EXIT INT TERM

rep=1
while [ "$rep" -le "$REPS" ]; do
  tag=A
  for bin in "$@"; do
    "$bin" -q extract "$VOLUME" --iso "$ISO" -o "$MESH" --stats "$WORK/$tag.$rep.json"
    stat -c %s "$MESH" > "$WORK/$tag.$rep.size"
    md5sum < "$MESH" | cut -d' ' -f1 > "$WORK/$tag.$rep.md5"
    rm -f "$MESH"
    tag=B
  done
  rep=$((rep + 1))
done

python3 - "$WORK" "$REPS" "$VOLUME" "$#" <<'PY'
import json, os, statistics, sys
work, reps, volume, nbins = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
SIZES = {"int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4, "uint32": 4, "float32": 4,
         "float64": 8}
tags = "AB"[:nbins]
rates = {t: {"read": [], "write": [], "measure": []} for t in tags}
stats = {}
for t in tags:
    for r in range(1, reps + 1):
        j = json.load(open(f"{work}/{t}.{r}.json"))
        size = int(open(f"{work}/{t}.{r}.size").read())
        s = j["seconds"]
        # The samples' bytes (a gzip'd file's decompressed size).
        vol_bytes = j["dims"][0] * j["dims"][1] * j["dims"][2] * SIZES[j["type"]]
        read, write, measure = vol_bytes / s["read"] / 1e9, size / s["write"] / 1e9, \
            j["triangles"] / s["measure"] / 1e6
        rates[t]["read"].append(read)
        rates[t]["write"].append(write)
        rates[t]["measure"].append(measure)
        print(f"{t} run {r}: read {read:5.2f} GB/s  write {write:5.2f} GB/s  measure "
              f"{measure:6.2f} Mtri/s  peak RSS {j['peak_rss_mb']:7.0f} MB  seconds "
              + " ".join(f"{k} {v:.2f}" for k, v in s.items()))
        key = {k: v for k, v in j.items() if k not in ("seconds", "peak_rss_mb", "output")}
        stats.setdefault(t, []).append((key, open(f"{work}/{t}.{r}.md5").read().strip()))
for t in tags:
    m = {k: statistics.median(v) for k, v in rates[t].items()}
    print(f"{t} median: read {m['read']:.2f} GB/s  write {m['write']:.2f} GB/s  "
          f"measure {m['measure']:.2f} Mtri/s")
if nbins == 2:
    ratio = {k: statistics.median(rates["B"][k]) / statistics.median(rates["A"][k])
             for k in rates["A"]}
    print("B/A rate: " + "  ".join(f"{k} {v:.2f}x" for k, v in ratio.items()))
    same = all(x == stats["A"][0] for x in stats["A"] + stats["B"])
    print("meshes and stats identical" if same else "MESHES OR STATS DIFFER")
    sys.exit(0 if same else 1)
PY
