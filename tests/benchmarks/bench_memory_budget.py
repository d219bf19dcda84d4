#!/usr/bin/env python3
"""Peak RSS above the budget's baseline: the out-of-core runs that CliMemory bounds, measured.

    tests/benchmarks/bench_memory_budget.py RUNS ISOTILE_A [ISOTILE_B]
    e.g. tests/benchmarks/bench_memory_budget.py 3 old/isotile build/tiler/isotile

For each case of tests/test_cli_memory.cpp (the same commands and budgets), runs the command on
its tiny input (the baseline: the same code mapped and touched) and on the real one, RUNS times
per binary, alternating binaries so that both see the same load, and prints the peak RSS
(`--stats` key peak_rss_mb) above the baseline as min-max in MiB beside the budget. The children
run with ASLR off (`setarch -R`), as the test runs them, so that which library pages are mapped
stays the same from run to run. Exit status 1 when a binary's largest value passes its budget.
"""
import gzip
import json
import math
import os
import shlex
import subprocess
import sys
import tempfile


def write_waves(directory, n):
    # The test's gzip'd n^3 uint8 volume of smooth waves (CliWaves::write_waves).
    v = bytearray(n * n * n)
    for z in range(n):
        for y in range(n):
            for x in range(n):
                s = (math.sin(0.2 * x) * math.cos(0.2 * y) + math.sin(0.2 * y) * math.cos(0.2 * z) +
                     math.sin(0.2 * z) * math.cos(0.2 * x))
                v[(z * n + y) * n + x] = int(math.floor(128 + 80 * s + 0.5))
    name = os.path.join(directory, f"waves_{n}x{n}x{n}_uint8.raw.gz")
    with gzip.open(name, "wb") as f:
        f.write(bytes(v))
    return name


def peak(binary, args, directory):
    # Through a shell that forks the command (a command follows it): the kernel's high-water mark
    # (ru_maxrss) survives exec, and Python spawns its children with vfork, so a command exec'd
    # from here would report this interpreter's peak where its own is smaller.
    command = " ".join(shlex.quote(a) for a in ["setarch", "-R", binary, "extract", *args, "-q",
                                                 "--stats", "-"])
    r = subprocess.run(["sh", "-c", command + "; status=$?; exit $status"], capture_output=True,
                       text=True, cwd=directory)
    if r.returncode != 0:
        sys.exit(f"{binary} extract {' '.join(args)}: exit {r.returncode}\n{r.stderr}")
    return json.loads(r.stdout)["peak_rss_mb"]


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__.split("\n\n")[1])
    runs = int(sys.argv[1])
    binaries = [os.path.abspath(b) for b in sys.argv[2:]]
    with tempfile.TemporaryDirectory() as d:
        waves, tiny_waves = write_waves(d, 128), write_waves(d, 12)
        gyroid = "field:gyroid:12"
        cases = [
            ("field:gyroid:200", gyroid, "--method mc --memory 8MiB", 8, "ply"),
            ("field:gyroid:200", gyroid, "--method macet --memory 8MiB", 8, "ply"),
            ("field:gyroid:200", gyroid, "--method dc --memory 8MiB", 8, "ply"),
            ("field:gyroid:200", gyroid, "--method mc --memory 8MiB", 8, "stl"),
            ("field:gyroid:256", gyroid, "--method mc --simplify 0.25 --memory 16MiB", 16, "ply"),
            ("field:gyroid:80", gyroid, "--method macet --quality max --memory 10MiB", 10, "ply"),
            (waves, tiny_waves, "--iso 128.5 --method mc --memory 4MiB", 4, "ply"),
            (waves, tiny_waves, "--iso 128.5 --method macet --memory 4MiB", 4, "ply"),
            (waves, tiny_waves, "--iso 128.5 --method dc --memory 4MiB", 4, "ply"),
        ]
        over_budget = False
        print("case | budget MiB | " + " | ".join(f"above baseline, MiB ({b})" for b in binaries))
        for big, tiny, options, budget, fmt in cases:
            above = {b: [] for b in binaries}
            for _ in range(runs):
                for b in binaries:
                    base = peak(b, [tiny, *options.split(), "-o", "tiny." + fmt], d)
                    above[b].append(peak(b, [big, *options.split(), "-o", "out." + fmt], d) - base)
            name = f"{os.path.basename(big)} {options} {fmt}"
            cells = [f"{min(v):.2f}-{max(v):.2f}" for v in above.values()]
            print(f"{name} | {budget} | " + " | ".join(cells), flush=True)
            over_budget |= any(max(v) > budget for v in above.values())
    return 1 if over_budget else 0


if __name__ == "__main__":
    sys.exit(main())
