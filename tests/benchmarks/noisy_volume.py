#!/usr/bin/env python3
"""Writes a noisy uint8 volume like an MRI or CT scan: uniform noise box-blurred PASSES times with
radius RADIUS along each axis, plus DETAIL times a second noise blurred once with radius 1,
stretched to [0, 255] and floored (the generator of tests/test_macet.cpp's noisy volumes, with
Python's random numbers instead of std::mt19937's). Pure Python: a 48^3 volume takes seconds.

usage: noisy_volume.py OUT.raw N SEED [PASSES RADIUS DETAIL]
"""
import random
import sys


def blurred(n, seed, passes, radius):
    rng = random.Random(seed)
    v = [rng.uniform(0.0, 255.0) for _ in range(n * n * n)]
    stride = (1, n, n * n)
    for _ in range(passes):
        for a in range(3):
            t = [0.0] * len(v)
            for k in range(n):
                for j in range(n):
                    for i in range(n):
                        c = (i, j, k)
                        at = i + j * n + k * n * n
                        lo, hi = max(c[a] - radius, 0), min(c[a] + radius, n - 1)
                        s = 0.0
                        for q in range(lo - c[a], hi - c[a] + 1):
                            s += v[at + q * stride[a]]
                        t[at] = s / (hi - lo + 1)
            v = t
    lo, hi = min(v), max(v)
    return [(x - lo) / (hi - lo) * 255.0 for x in v]


def main():
    out, n, seed = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    passes = int(sys.argv[4]) if len(sys.argv) > 4 else 3
    radius = int(sys.argv[5]) if len(sys.argv) > 5 else 2
    detail = float(sys.argv[6]) if len(sys.argv) > 6 else 1.0
    v = blurred(n, seed, passes, radius)
    w = blurred(n, seed + 1000, 1, 1)
    data = bytes(min(255, int((x + detail * y) / (1 + detail))) for x, y in zip(v, w))
    with open(out, "wb") as f:
        f.write(data)


if __name__ == "__main__":
    main()
