#!/bin/sh
# Out-of-core throughput at scale (issue 19's case): a 4 GiB volume made by repeating bonsai
# 8 x 8 x 4 times (2048 x 2048 x 1024 uint8, 181M triangles at 49.5), extracted with 2 threads.
#
#   tests/benchmarks/bench_tiler_scale.sh [ISOTILE] [OTHER_ISOTILE] [DISK_DIR]
#   defaults: build/tiler/isotile, none, none
#
# Runs, each in a fresh process, output on tmpfs (/dev/shm): MC and Macet fast with --memory 1GiB,
# then MC in core; with OTHER_ISOTILE (e.g. an older build) the same runs of it alternate with
# these, side by side. With DISK_DIR, the MC 1 GiB run again with its output there (on disk).
# Prints each run's seconds.total, triangles per second of it, peak RSS and the per-stage split
# of --stats (read, count, extract, index, records, write: busy seconds summed over bricks, which
# overlap in time), and for in-core runs read and write throughput.
#
# The volume is made once with ../shared/tools/tile_volume.py (Debian's python3-numpy) into
# ${ISOTILE_BENCH_DIR:-/var/tmp}; it needs 4 GiB of disk and the page cache to hold it (the
# figures are for reads from the page cache: the file is read once before timing).
set -eu
ISOTILE=${1:-build/tiler/isotile}
OTHER=${2:-}
DISK=${3:-}
HERE=$(cd "$(dirname "$0")" && pwd)
SHARED=$HERE/../../../shared
DIR=${ISOTILE_BENCH_DIR:-/var/tmp}
VOL=$DIR/bonsai-tiled_2048x2048x1024_uint8.raw
if [ ! -f "$VOL" ]; then
  if [ ! -f "$SHARED/data/bonsai_256x256x256_uint8.raw.gz" ] || [ ! -f "$SHARED/tools/tile_volume.py" ]; then
    echo "bench_tiler_scale: needs ../shared/data/bonsai and ../shared/tools/tile_volume.py; skipped"
    exit 0
  fi
  /usr/bin/python3 "$SHARED/tools/tile_volume.py" "$SHARED/data/bonsai_256x256x256_uint8.raw.gz" 8 8 4 "$DIR"
fi
cat "$VOL" > /dev/null
OUT=/dev/shm/isotile-bench-$$
mkdir -p "$OUT"
trap 'rm -rf "$OUT"' EXIT INT TERM

run() {  # label binary outdir args...
  label=$1
  bin=$2
  dir=$3
  shift 3
  /usr/bin/time -f "%e %M" -o "$OUT/time" "$bin" -q extract "$VOL" --iso 49.5 --threads 2 \
    -o "$dir/out.ply" --stats "$OUT/stats.json" "$@"
  rm -f "$dir/out.ply"
  read -r wall kib < "$OUT/time"
  /usr/bin/python3 - "$label" "$wall" "$kib" "$OUT/stats.json" <<'EOF'
import json, sys
label, wall, kib, path = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
d = json.load(open(path))
s = d["seconds"]
tris = d["triangles"]
line = f"{label:<28} total {s['total']:7.2f} s  {tris / s['total'] / 1e6:6.1f} M tri/s  " \
       f"wall {wall:6.2f} s  RSS {kib / 1024:6.0f} MB"
if "stages" in s:
    st = s["stages"]
    line += "  | " + " ".join(f"{k} {st[k]:.2f}" for k in
                              ("read", "count", "extract", "index", "records", "write"))
elif "read" in s:
    gb_in = d["dims"][0] * d["dims"][1] * d["dims"][2] / 1e9
    # Binary PLY: 12 bytes a vertex, 13 a triangle (plus the header).
    gb_out = (12 * d["vertices"] + 13 * tris) / 1e9
    line += f"  | read {s['read']:.2f} ({gb_in / s['read']:.2f} GB/s) extract {s['extract']:.2f}" \
            f" write {s['write']:.2f} ({gb_out / s['write']:.2f} GB/s) measure {s['measure']:.2f}" \
            f" ({tris / s['measure'] / 1e6:.1f} M tri/s)"
print(line, flush=True)
EOF
}

both() {  # label outdir args...: this build, then OTHER_ISOTILE, side by side
  label=$1
  dir=$2
  shift 2
  run "this $label" "$ISOTILE" "$dir" "$@"
  if [ -n "$OTHER" ]; then run "other $label" "$OTHER" "$dir" "$@"; fi
}

both "mc --memory 1GiB" "$OUT" --memory 1GiB
both "macet --memory 1GiB" "$OUT" --method macet --memory 1GiB
if [ -n "$DISK" ]; then both "mc 1GiB to disk" "$DISK" --memory 1GiB; fi
both "mc in core" "$OUT"
