#!/bin/sh
# Distributed extraction benchmark: one process against mpirun with 1 and 2 ranks (one TBB
# thread each, so that 2 ranks use this machine's 2 cores and no more), on the same volume and
# budget; checks the files are identical; then projects 16-256 ranks from the per-brick seconds
# the 1-rank run measured (its --stats), with the model printed below.
#
#   tests/benchmarks/bench_mpi.sh [ISOTILE] [INPUT] [BUDGET] [EXTRA ARGS...]
#   defaults: build/tiler/isotile, bonsai (../shared/data, decompressed into a temporary folder)
#             at iso 40, or field:gyroid:256 where the shared data is absent; 1MiB (~500 bricks)
#
# The projection (strong scaling: this volume, this plan) takes, for K ranks:
#   count   = the slowest rank's sum of measured count seconds over its contiguous block
#   extract = the slowest rank's sum of measured extract seconds over the bricks the balancer
#             gives it (the program's own rule: brick_cost, longest first to the least loaded)
#   comm    = the tables' allreduce and the agreements: 2 S / B + 16 log2(K) L, with S the
#             tables' bytes, B = 10 GB/s and L = 2 us (a 100 Gb/s InfiniBand link)
# Assumed: reads and writes scale with the ranks (a parallel file system), no rank shares a core,
# MPI start-up is excluded (measured here, printed, and site-dependent). Measured per-brick times
# on this shared 2-core machine are noisy.
set -eu
ISOTILE=${1:-build/tiler/isotile}
INPUT=${2:-}
BUDGET=${3:-1MiB}
[ $# -gt 3 ] && shift 3 || set --
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT INT TERM
SHARED=$(dirname "$0")/../../../shared/data
if [ -z "$INPUT" ]; then
  if [ -f "$SHARED/bonsai_256x256x256_uint8.raw.gz" ]; then
    gzip -dc "$SHARED/bonsai_256x256x256_uint8.raw.gz" > "$OUT/bonsai_256x256x256_uint8.raw"
    set -- --iso 40 "$@"
    INPUT="$OUT/bonsai_256x256x256_uint8.raw"
  else
    INPUT=field:gyroid:256
  fi
fi
MPIRUN="mpirun --allow-run-as-root --oversubscribe --mca pml ob1 --mca btl self,vader"

cut -d' ' -f1-3 /proc/loadavg > "$OUT/load.before"

timed() {  # name command...
  name=$1
  shift
  /usr/bin/time -f "%e" -o "$OUT/$name.time" "$@"
}
timed plain "$ISOTILE" -q --threads 1 extract "$INPUT" "$@" --memory "$BUDGET" -o "$OUT/plain.ply"
timed plain2 "$ISOTILE" -q --threads 2 extract "$INPUT" "$@" --memory "$BUDGET" -o "$OUT/plain2.ply"
for k in 1 2; do
  timed "mpi$k" $MPIRUN -np "$k" "$ISOTILE" -q --threads 1 extract "$INPUT" "$@" \
    --memory "$BUDGET" -o "$OUT/mpi$k.ply" --stats "$OUT/mpi$k.json"
  cmp "$OUT/plain.ply" "$OUT/mpi$k.ply"
done
cut -d' ' -f1-3 /proc/loadavg > "$OUT/load.after"

python3 - "$OUT" <<'EOF'
import json, math, sys
out = sys.argv[1]
t = {n: float(open(f"{out}/{n}.time").read().split()[0]) for n in ("plain", "plain2", "mpi1", "mpi2")}
s1 = json.load(open(f"{out}/mpi1.json"))
s2 = json.load(open(f"{out}/mpi2.json"))
print(f"input {s1['input']} {s1['dims']} iso {s1['iso']}, {s1['method']}, budget "
      f"{s1['memory_budget']} B: {s1['bricks']} bricks of {s1['brick_cells']} cells, "
      f"{s1['triangles']} triangles; files identical")
load = [open(f"{out}/load.{w}").read().strip() for w in ("before", "after")]
print(f"measured here (wall seconds, shared 2-core machine, 1 TBB thread per rank; load average "
      f"{load[0]} before, {load[1]} after):")
print(f"  1 process, 1 thread        {t['plain']:7.2f} s")
print(f"  1 process, 2 threads       {t['plain2']:7.2f} s")
print(f"  mpirun -np 1               {t['mpi1']:7.2f} s  (MPI start-up and MPI-IO: "
      f"{t['mpi1'] - t['plain']:+.2f} s)")
print(f"  mpirun -np 2               {t['mpi2']:7.2f} s  speed-up over -np 1: "
      f"{t['mpi1'] / t['mpi2']:.2f}")
for k, s in ((1, s1), (2, s2)):
    ranks = ", ".join(f"r{i}: count {r['seconds_count']:.2f} extract {r['seconds_extract']:.2f} "
                      f"({r['bricks_extracted']} bricks)" for i, r in enumerate(s['per_rank']))
    print(f"  -np {k} phases: count {s['seconds']['count']:.2f} s extract "
          f"{s['seconds']['extract']:.2f} s; {ranks}; imbalance {s['load_imbalance']:.3f} "
          f"(planned {s['load_imbalance_planned']:.3f})")

# Per-brick measurements of the 1-rank run.
count = s1["brick_seconds"]["count"]
extract = s1["brick_seconds"]["extract"]
faces = s1["brick_faces"]
dims, brick, grid = s1["dims"], s1["brick_cells"], s1["brick_grid"]
B = len(count)
def cells(b):
    idx = (b % grid[0], b // grid[0] % grid[1], b // grid[0] // grid[1])
    n = 1
    for a in range(3):
        lo = idx[a] * brick[a]
        n *= min(lo + brick[a], dims[a] - 1) - lo
    return n
ncells = [cells(b) for b in range(B)]
# The balance model's cost (tiler/mpi_extract.cpp: kCellCost), and a least-squares fit of the
# measured extract seconds to a * cells + b * faces, whose ratio a / b is what kCellCost stands for.
K_CELL = 0.1
sxx = sum(c * c for c in ncells); syy = sum(f * f for f in faces)
sxy = sum(c * f for c, f in zip(ncells, faces))
sxt = sum(c * e for c, e in zip(ncells, extract)); syt = sum(f * e for f, e in zip(faces, extract))
det = sxx * syy - sxy * sxy
if det > 0:
    a = (sxt * syy - syt * sxy) / det
    b = (syt * sxx - sxt * sxy) / det
    print(f"fit of extract seconds per brick: {a * 1e9:.2f} ns per cell + {b * 1e9:.1f} ns per "
          f"face (cell/face cost ratio {a / b if b > 0 else float('nan'):.3f}; the balancer uses "
          f"{K_CELL})")
cost = [K_CELL * c + f for c, f in zip(ncells, faces)]
order = sorted(range(B), key=lambda i: -cost[i])  # stable: ties by index, as the program
table_bytes = 2 * 8 * (dims[1] * dims[2] * grid[0] + 1) + 2 * 8 * B
BW, LAT = 10e9, 2e-6

def model(K):
    tc = max(sum(count[B * r // K:B * (r + 1) // K]) for r in range(K))
    load = [0.0] * K
    secs = [0.0] * K
    for i in order:
        r = min(range(K), key=lambda x: load[x])
        load[r] += cost[i]
        secs[r] += extract[i]
    te = max(secs)
    comm = 2 * table_bytes / BW + 16 * math.log2(K) * LAT if K > 1 else 0.0
    mean = sum(secs) / K
    return tc, te, comm, te / mean if mean > 0 else 1.0

t1 = sum(model(1)[:3])
print("projected from the 1-rank run's per-brick seconds (model above; not measured):")
print("  ranks   count  extract     comm    total  speed-up  efficiency  extract imbalance")
for K in (1, 2, 16, 32, 64, 128, 256):
    tc, te, comm, imb = model(K)
    tot = tc + te + comm
    print(f"  {K:5d} {tc:7.3f} {te:8.3f} {comm:8.4f} {tot:8.3f} {t1 / tot:9.1f} "
          f"{t1 / tot / K:11.2f} {imb:18.2f}")
print(f"  largest brick's extract {max(extract):.3f} s bounds the extract phase from below; "
      f"model at 2 ranks vs measured phases: {sum(model(2)[:3]):.2f} s vs "
      f"{s2['seconds']['count'] + s2['seconds']['extract']:.2f} s")
EOF
