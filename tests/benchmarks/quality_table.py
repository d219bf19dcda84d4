#!/usr/bin/env python3
"""Regenerates the real-volume quality table of docs/quality.md (the paper's Table I and more).

Runs `isotile extract ... --check-intersections --stats` for every volume and method below and
prints one markdown row per run from the stats JSON (keys as in docs/cli.md). A method the CLI
rejects (e.g. Macet before it is built in) gets a row marked "pending" with the CLI's message, so
the table fills in by itself once the method lands.

  tests/benchmarks/quality_table.py [--isotile build/tiler/isotile] [--data ../shared/data]
                                    [--threads 2] [--only bonsai,engine] [--iso 50] [--methods DC]
  tests/benchmarks/quality_table.py --fields [--sizes 32,64,128]

--fields instead measures every CLI method on the procedural fields: vertex distance to the exact
surface (stats keys distance_mean, distance_max, in voxels) and the radius ratio. (The sampled
symmetric surface distance and DC's Hermite options are in bench_quality, which links the library.)
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

# (name, file, isovalue): the paper's two at 49.5, then more real volumes of other kinds.
VOLUMES = [
    ("bonsai", "bonsai_256x256x256_uint8.raw.gz", 49.5),
    ("engine", "engine_256x256x128_uint8.raw.gz", 49.5),
    ("stent", "stent_128x128x256_int16.raw.gz", 500.5),
    ("lobster", "lobster_301x324x56_uint8.raw.gz", 40.5),
    ("aneurism", "aneurism_256x256x256_uint8.raw.gz", 100.5),
]

METHODS = [
    ("MC", ["--method", "mc"]),
    ("DC mass point, patch (default)", ["--method", "dc"]),
    ("DC particle (10 steps), patch", ["--method", "dc", "--dc-solver", "particle"]),
    ("DC QEF, patch", ["--method", "dc", "--dc-solver", "qef"]),
    ("DC mass point, cell", ["--method", "dc", "--dc-vertices", "cell"]),
    ("DC particle (10 steps), cell", ["--method", "dc", "--dc-solver", "particle",
                                      "--dc-vertices", "cell"]),
    ("DC QEF, cell", ["--method", "dc", "--dc-solver", "qef", "--dc-vertices", "cell"]),
    ("Macet fast", ["--method", "macet", "--quality", "fast"]),
    ("Macet max", ["--method", "macet", "--quality", "max"]),
    ("Macet max, relax 0.35", ["--method", "macet", "--quality", "max", "--macet-relax", "0.35"]),
]


def run(isotile, path, iso, args, threads, tmp):
    stats = os.path.join(tmp, "stats.json")
    mesh = os.path.join(tmp, "mesh.ply")
    cmd = [isotile, "--threads", str(threads), "--quiet", "extract", path, "--iso", str(iso),
           "-o", mesh, "--check-intersections", "--stats", stats] + args
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        return None, (p.stderr.strip().splitlines() or ["exit %d" % p.returncode])[-1]
    with open(stats) as f:
        return json.load(f), None


FIELDS = ["sphere", "torus", "gyroid", "csg-box"]


def fields_table(a):
    print("| field | N | method | vertex mean | vertex max | q mean | q min | self-int. |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for field in FIELDS:
            for n in [int(x) for x in a.sizes.split(",")]:
                for label, args in METHODS:
                    stats = os.path.join(tmp, "stats.json")
                    cmd = [a.isotile, "--threads", str(a.threads), "--quiet", "extract",
                           "field:%s:%d" % (field, n), "-o", os.path.join(tmp, "m.ply"),
                           "--check-intersections", "--stats", stats] + args
                    p = subprocess.run(cmd, capture_output=True, text=True)
                    if p.returncode != 0:
                        err = (p.stderr.strip().splitlines() or ["exit %d" % p.returncode])[-1]
                        print("| %s | %d | %s | pending (%s) | | | | |" % (field, n, label, err))
                        continue
                    with open(stats) as f:
                        j = json.load(f)
                    print("| %s | %d | %s | %.4f | %.4f | %.3f | %.3g | %d |" % (
                        field, n, label, j["distance_mean"], j["distance_max"],
                        j["radius_ratio_mean"], j["radius_ratio_min"], j["self_intersections"]))
                    sys.stdout.flush()


def main():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--isotile", default=os.path.join(root, "build", "tiler", "isotile"))
    ap.add_argument("--data", default=os.environ.get(
        "ISOTILE_SHARED_DATA", os.path.join(root, "..", "shared", "data")))
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--only", default="", help="comma-separated volume names")
    ap.add_argument("--iso", type=float, default=None,
                    help="one isovalue for every volume instead of their own (e.g. 50: samples "
                         "equal to it, docs/quality.md)")
    ap.add_argument("--methods", default="",
                    help="only the methods whose label contains this text (e.g. DC)")
    ap.add_argument("--fields", action="store_true", help="procedural fields instead")
    ap.add_argument("--sizes", default="32,64,128", help="grid sizes for --fields")
    a = ap.parse_args()
    METHODS[:] = [m for m in METHODS if a.methods in m[0]]
    if a.fields:
        return fields_table(a)
    only = set(filter(None, a.only.split(",")))

    print("| volume | iso | method | triangles | degenerate | min | 0.1% | 1% | mean | self-int. | "
          "non-manifold edges | extract s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for name, file, own_iso in VOLUMES:
            iso = own_iso if a.iso is None else a.iso
            if only and name not in only:
                continue
            path = os.path.join(a.data, file)
            if not os.path.exists(path):
                print("skipping %s: %s not found" % (name, path), file=sys.stderr)
                continue
            for label, args in METHODS:
                j, err = run(a.isotile, path, iso, args, a.threads, tmp)
                if j is None:
                    print("| %s | %g | %s | pending (%s) | | | | | | | | |" % (name, iso, label, err))
                    continue
                print("| %s | %g | %s | %d | %d | %.3g | %.3f | %.3f | %.3f | %d | %d | %.3f |" % (
                    name, iso, label, j["triangles"], j["degenerate_triangles"],
                    j["radius_ratio_min"],
                    j["radius_ratio_q001"], j["radius_ratio_q01"], j["radius_ratio_mean"],
                    j["self_intersections"], j["nonmanifold_edges"], j["seconds"]["extract"]))
                sys.stdout.flush()


if __name__ == "__main__":
    main()
