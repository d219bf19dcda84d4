#!/usr/bin/python3
"""isotile's Python module against scikit-image and VTK, in one process (docs/python.md).

    PYTHONPATH=build/python /usr/bin/python3 tests/benchmarks/bench_python.py [--threads 2]
        [--repeats 5] [--data ../shared/data]

Volumes: bonsai 256^3 uint8 at 49.5 (from --data) and a gyroid 256^3 float32 at 0 made with
NumPy. Every time is the median of --repeats runs (scikit-image: 3), wall clock, warm (one
untimed run first). Outputs are alike on every side: vertices, faces, normals (scikit-image
always computes them; VTK's vtkFlyingEdges3D with ComputeNormals on, ComputeScalars off), the
arrays handed to NumPy (VTK's through vtk.util.numpy_support), and isotile's `values` besides.

A second table times one thread in CPU time, which the load of a shared machine changes little.

The binding's overhead: the module's marching_cubes() against the same library calls (value
range, extract, values) timed inside C++ on the same array in this process
(isotile._isotile._time_library_calls, no Python layer, no array wrapping), the fastest of
2 x --repeats interleaved runs of each.
"""
import argparse
import gzip
import os
import pathlib
import statistics
import sys
import time

import numpy as np

import isotile
from isotile import _isotile


def median_time(fn, repeats, clock=time.perf_counter):
    fn()
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return statistics.median(times)


def overhead(vol, level, threads, pairs):
    """Fastest of `pairs` interleaved runs of the module's marching_cubes() and of the same
    library calls timed inside C++ (the least disturbed run of each, which the load of a shared
    machine changes least): (Python call, C++ calls, C++ extract() alone), seconds."""
    py, cpp, ext = [], [], []
    isotile.marching_cubes(vol, level, threads=threads)
    for _ in range(pairs):
        t0 = time.perf_counter()
        isotile.marching_cubes(vol, level, threads=threads)
        py.append(time.perf_counter() - t0)
        (all_calls, extract_only), = _isotile._time_library_calls(vol, level, "mc", True,
                                                                  threads, 1)
        cpp.append(all_calls)
        ext.append(extract_only)
    return min(py), min(cpp), min(ext)


def gyroid(n=256):
    u = np.linspace(-1.0, 1.0, n)
    w = 2 * np.pi
    z, y, x = np.meshgrid(w * u, w * u, w * u, indexing="ij", sparse=True)
    return (np.sin(x) * np.cos(y) + np.sin(y) * np.cos(z) + np.sin(z) * np.cos(x)).astype(
        np.float32)


def vtk_flying_edges(threads):
    try:
        import vtk
        from vtk.util import numpy_support
    except ImportError:
        return None
    vtk.vtkSMPTools.Initialize(threads)

    def run(vol, level):
        image = vtk.vtkImageData()
        z, y, x = vol.shape
        image.SetDimensions(x, y, z)
        image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(vol.reshape(-1), deep=False))
        fe = vtk.vtkFlyingEdges3D()
        fe.SetInputData(image)
        fe.SetValue(0, level)
        fe.ComputeNormalsOn()
        fe.ComputeGradientsOff()
        fe.ComputeScalarsOff()
        fe.Update()
        out = fe.GetOutput()
        verts = numpy_support.vtk_to_numpy(out.GetPoints().GetData())
        faces = numpy_support.vtk_to_numpy(out.GetPolys().GetConnectivityArray())
        normals = numpy_support.vtk_to_numpy(out.GetPointData().GetNormals())
        return verts, faces.reshape(-1, 3), normals

    return run, vtk.vtkSMPTools.GetBackend()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--data", default=str(pathlib.Path(__file__).resolve().parents[2].parent /
                                          "shared" / "data"))
    args = ap.parse_args()
    from skimage.measure import marching_cubes as sk_mc

    volumes = []
    bonsai = pathlib.Path(args.data) / "bonsai_256x256x256_uint8.raw.gz"
    if bonsai.exists():
        with gzip.open(bonsai, "rb") as f:
            volumes.append(("bonsai", np.frombuffer(f.read(), np.uint8).reshape(256, 256, 256),
                            49.5))
    else:
        print(f"bench_python: no {bonsai}; gyroid only", file=sys.stderr)
    volumes.append(("gyroid", gyroid(), 0.0))
    vtk_run = vtk_flying_edges(args.threads)
    t = args.threads
    print(f"threads {t}; {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f} at the "
          f"start; median of {args.repeats} (scikit-image: 3); "
          f"VTK SMP backend: {vtk_run[1] if vtk_run else 'python3-vtk9 not installed'}")
    print("| volume | triangles | scikit-image | isotile MC | speed-up | MC, normals=False | speed-up "
          "| C++ calls (min) | overhead (min vs min) | C++ extract() (min) | VTK Flying Edges "
          "| isotile Macet | isotile DC |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, vol, level in volumes:
        faces = len(isotile.marching_cubes(vol, level, threads=t)[1])
        sk = median_time(lambda: sk_mc(vol, level), 3)
        mc = median_time(lambda: isotile.marching_cubes(vol, level, threads=t), args.repeats)
        bare = median_time(lambda: isotile.marching_cubes(vol, level, threads=t, normals=False),
                           args.repeats)
        py_min, cpp_all, cpp_extract = overhead(vol, level, t, 2 * args.repeats)
        fe = (median_time(lambda: vtk_run[0](vol, level), args.repeats) if vtk_run else None)
        macet = median_time(lambda: isotile.marching_cubes(vol, level, method="macet", threads=t),
                            args.repeats)
        dc = median_time(lambda: isotile.marching_cubes(vol, level, method="dc", threads=t),
                         args.repeats)
        ms = lambda s: f"{s * 1e3:.1f} ms"
        print(f"| {name} | {faces:,} | {ms(sk)} | {ms(mc)} | {sk / mc:.1f}x | {ms(bare)} | "
              f"{sk / bare:.1f}x | {ms(cpp_all)} | "
              f"{(py_min / cpp_all - 1) * 100:+.1f}% | {ms(cpp_extract)} | "
              f"{ms(fe) if fe else 'n/a'} | {ms(macet)} | {ms(dc)} |")


    # The same work on one thread, in CPU time (time.process_time): what each side costs, whatever
    # else the machine is running (wall-clock times above grow with the load average).
    print()
    print("| volume | scikit-image, CPU s | isotile MC threads=1, CPU s | ratio | normals=False, CPU s "
          "| ratio |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    cpu = time.process_time
    for name, vol, level in volumes:
        sk = median_time(lambda: sk_mc(vol, level), 3, cpu)
        mc = median_time(lambda: isotile.marching_cubes(vol, level, threads=1), args.repeats, cpu)
        bare = median_time(lambda: isotile.marching_cubes(vol, level, threads=1, normals=False),
                           args.repeats, cpu)
        print(f"| {name} | {sk:.3f} | {mc:.3f} | {sk / mc:.1f}x | {bare:.3f} | {sk / bare:.1f}x |")
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
