#!/usr/bin/env python3
"""ctest Figures.MakeFiguresMakesValidPictures: runs docs/make_figures.sh into a temporary folder
(never over the committed pictures) and checks that it succeeds and that every picture it makes
is a valid PNG (signature, CRCs, pixel data) of the committed copy's size in docs/images, with
the mesh covering most of it. Exits 77 (skipped) without an OpenGL context or the shared volumes,
unless ISOTILE_STRICT_SKIPS demands them (gl, shared-data, all), as tests/skip_support.h does.

    check_figures.py ISOTILE
"""
import os
import subprocess
import sys
import tempfile

repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(repo, "docs"))
import compose_png  # noqa: E402


def skip(kind, why):
    strict = os.environ.get("ISOTILE_STRICT_SKIPS", "").split(",")
    if "all" in strict or kind in strict:
        print(f"check_figures: cannot run ({kind} is required by ISOTILE_STRICT_SKIPS): {why}")
        sys.exit(1)
    print(f"check_figures: skipped: {why}")
    sys.exit(77)


def main():
    isotile = os.path.abspath(sys.argv[1])
    info = subprocess.run([isotile, "gl-info"], capture_output=True, text=True)
    if info.returncode != 0:
        skip("gl", "isotile gl-info found no OpenGL: " + info.stderr.strip())
    with tempfile.TemporaryDirectory() as out:
        run = subprocess.run([os.path.join(repo, "docs", "make_figures.sh"), out],
                             env=dict(os.environ, ISOTILE=isotile), capture_output=True,
                             text=True)
        if run.returncode == 77:
            skip("shared-data", run.stderr.strip())
        if run.returncode != 0:
            print(f"check_figures: make_figures.sh failed ({run.returncode}):\n{run.stderr}")
            return 1
        names = sorted(n for n in os.listdir(out) if n.endswith(".png"))
        if not names:
            print("check_figures: make_figures.sh made no picture")
            return 1
        failures = 0
        for name in names:
            try:
                w, h, rows = compose_png.read_png(os.path.join(out, name))
                committed = os.path.join(repo, "docs", "images", name)
                cw, ch, _ = compose_png.read_png(committed)
            except (OSError, ValueError) as e:
                print(f"check_figures: {name}: {e}")
                failures += 1
                continue
            covered = sum(1 for row in rows for i in range(0, len(row), 3)
                          if row[i:i + 3] != b"\xff\xff\xff")
            same = open(os.path.join(out, name), "rb").read() == open(committed, "rb").read()
            print(f"check_figures: {name}: {w}x{h}, {covered / (w * h):.1%} covered, "
                  f"{'identical to' if same else 'differs from'} the committed copy")
            if (w, h) != (cw, ch):
                print(f"check_figures: {name}: {w}x{h}, the committed copy is {cw}x{ch}")
                failures += 1
            if covered < 0.5 * w * h:
                print(f"check_figures: {name}: the mesh covers under half of the picture")
                failures += 1
        return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
