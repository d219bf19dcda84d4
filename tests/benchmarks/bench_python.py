#!/usr/bin/python3
"""isotile's Python module against scikit-image and VTK, in one process (docs/python.md).

    PYTHONPATH=build/python /usr/bin/python3 tests/benchmarks/bench_python.py [--threads 2]
        [--repeats 5] [--data ../shared/data] [--baseline other-build/python]

Volumes: bonsai 256^3 uint8 at 49.5 (from --data) and a gyroid 256^3 float32 at 0 made with
NumPy. Every time is the median of --repeats runs (scikit-image: 3), wall clock, warm (one
untimed run first). Outputs are alike on every side: vertices, faces, normals (scikit-image
always computes them; VTK's vtkFlyingEdges3D with ComputeNormals on, ComputeScalars off), the
arrays handed to NumPy (VTK's through vtk.util.numpy_support), and isotile's `values` besides.

A second table times one thread in CPU time, which the load of a shared machine changes little.

The binding's overhead: the module's marching_cubes() against the same library calls (the
samples' finite check and range in one pass, extract, values) timed inside C++ on the same array
in this process (isotile._isotile._time_library_calls, no Python layer, no array wrapping), the
fastest of 2 x --repeats interleaved runs of each. A breakdown table gives each of those calls
(fastest run), extract() without normals, and what the module adds (Python layer, arrays).

Cold: the first marching_cubes() of a fresh process (`import isotile` and reading the volume
excluded: TBB's threads start, the library's code and buffers are first touched), beside
scikit-image's first call in another fresh process.

--baseline: another build's package (e.g. one of the commit before a change) timed beside this
build's, call by call in this process, warm and cold.
"""
import argparse
import gzip
import importlib.util
import inspect
import os
import pathlib
import statistics
import subprocess
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


def overhead(vol, level, threads, pairs, normals=True):
    """Fastest of `pairs` interleaved runs of the module's marching_cubes() and of the same
    library calls timed inside C++ (the least disturbed run of each, which the load of a shared
    machine changes least): (Python call, C++ calls, (checks, extract(), values) of the fastest
    C++ run), seconds."""
    py, cpp = [], []
    isotile.marching_cubes(vol, level, threads=threads, normals=normals)
    for _ in range(pairs):
        t0 = time.perf_counter()
        isotile.marching_cubes(vol, level, threads=threads, normals=normals)
        py.append(time.perf_counter() - t0)
        steps, = _isotile._time_library_calls(vol, level, "mc", normals, threads, 1)
        cpp.append((sum(steps[:3]), steps[:3]))
    fastest = min(cpp)
    return min(py), fastest[0], fastest[1]


def cpu_steps(vol, level, repeats, normals=True):
    """CPU seconds of (checks, extract(), values) at one thread, each the fastest of `repeats`."""
    runs = _isotile._time_library_calls(vol, level, "mc", normals, 1, repeats)
    return [min(r[3 + i] for r in runs) for i in range(3)]


COLD = """
import gzip, sys, time
import numpy as np
sys.path[:0] = {path!r}
{load}
level = {level!r}
if {skimage!r}:
    from skimage.measure import marching_cubes as run
    t0 = time.perf_counter()
    run(vol, level)
else:
    import isotile
    t0 = time.perf_counter()
    isotile.marching_cubes(vol, level, threads={threads})
print(time.perf_counter() - t0)
"""


def cold_first_call(load, level, threads, skimage, path=None):
    """Seconds of the first call in a fresh interpreter (the import and the volume's making
    excluded); `path`: a folder whose isotile package is imported instead."""
    search = ([path] if path else []) + sys.path
    code = COLD.format(path=search, load=load, level=level, threads=threads, skimage=skimage)
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return float(out.stdout.split()[-1])


def load_baseline(folder):
    """The isotile package in `folder` (another build's <build>/python), as isotile_baseline."""
    init = pathlib.Path(folder) / "isotile" / "__init__.py"
    spec = importlib.util.spec_from_file_location("isotile_baseline", init,
                                                  submodule_search_locations=[str(init.parent)])
    module = importlib.util.module_from_spec(spec)
    sys.modules["isotile_baseline"] = module
    spec.loader.exec_module(module)
    return module


def baseline_table(base, folder, volumes, threads, repeats, sk_mc):
    """Another build's marching_cubes beside this one's and scikit-image's, interleaved call by
    call (the load of a shared machine falls on both alike): medians and fastest runs, and each
    one's cold first call in a fresh process."""
    print()
    print(f"This build against the one in {folder}, threads {threads}, {2 * repeats} interleaved "
          "calls each (median; fastest in brackets):")
    print("| volume | scikit-image | baseline | speed-up | this build | speed-up "
          "| baseline, cold | this build, cold |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, vol, level, load in volumes:
        sk = median_time(lambda: sk_mc(vol, level), 3)
        old, new = [], []
        base.marching_cubes(vol, level, threads=threads)
        isotile.marching_cubes(vol, level, threads=threads)
        for _ in range(2 * repeats):
            for module, out in ((base, old), (isotile, new)):
                t0 = time.perf_counter()
                module.marching_cubes(vol, level, threads=threads)
                out.append(time.perf_counter() - t0)
        cold_old = cold_first_call(load, level, threads, False, folder)
        cold_new = cold_first_call(load, level, threads, False)
        ms = lambda s: f"{s * 1e3:.1f} ms"
        mo, mn = statistics.median(old), statistics.median(new)
        print(f"| {name} | {ms(sk)} | {ms(mo)} ({ms(min(old))}) | {sk / mo:.1f}x | "
              f"{ms(mn)} ({ms(min(new))}) | {sk / mn:.1f}x | {ms(cold_old)} | {ms(cold_new)} |")


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
    ap.add_argument("--baseline", metavar="FOLDER",
                    help="another build's <build>/python: its marching_cubes timed beside this "
                         "one's (before/after a change), in this process")
    args = ap.parse_args()
    from skimage.measure import marching_cubes as sk_mc
    base = load_baseline(args.baseline) if args.baseline else None

    # (name, samples, level, the code that makes them as `vol` in a fresh process)
    volumes = []
    bonsai = pathlib.Path(args.data) / "bonsai_256x256x256_uint8.raw.gz"
    if bonsai.exists():
        with gzip.open(bonsai, "rb") as f:
            volumes.append(("bonsai", np.frombuffer(f.read(), np.uint8).reshape(256, 256, 256),
                            49.5, f"vol = np.frombuffer(gzip.open({str(bonsai)!r}).read(), "
                            "np.uint8).reshape(256, 256, 256)"))
    else:
        print(f"bench_python: no {bonsai}; gyroid only", file=sys.stderr)
    volumes.append(("gyroid", gyroid(), 0.0, inspect.getsource(gyroid) + "vol = gyroid()"))
    vtk_run = vtk_flying_edges(args.threads)
    t = args.threads
    print(f"threads {t}; {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f} at the "
          f"start; median of {args.repeats} (scikit-image: 3); "
          f"VTK SMP backend: {vtk_run[1] if vtk_run else 'python3-vtk9 not installed'}")
    print("| volume | triangles | scikit-image | isotile MC | speed-up | MC, normals=False | speed-up "
          "| C++ calls (min) | overhead (min vs min) | C++ extract() (min) | VTK Flying Edges "
          "| isotile Macet | isotile DC |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    breakdown = []
    for name, vol, level, _ in volumes:
        faces = len(isotile.marching_cubes(vol, level, threads=t)[1])
        sk = median_time(lambda: sk_mc(vol, level), 3)
        mc = median_time(lambda: isotile.marching_cubes(vol, level, threads=t), args.repeats)
        bare = median_time(lambda: isotile.marching_cubes(vol, level, threads=t, normals=False),
                           args.repeats)
        py_min, cpp_all, steps = overhead(vol, level, t, 2 * args.repeats)
        bare_py, bare_cpp, bare_steps = overhead(vol, level, t, 2 * args.repeats, normals=False)
        breakdown.append((name, py_min, cpp_all, steps, bare_py, bare_steps))
        cpp_extract = steps[1]
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

    print()
    print(f"Where a call's time goes, threads {t}, fastest of {2 * args.repeats} runs (C++ timers "
          "inside the library calls; the module: the Python call less those calls):")
    print("| volume | checks + range | extract() | extract(), no normals | values | C++ calls "
          "| module call | the module adds | module call, normals=False |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, py_min, cpp_all, steps, bare_py, bare_steps in breakdown:
        ms = lambda s: f"{s * 1e3:.1f} ms"
        print(f"| {name} | {ms(steps[0])} | {ms(steps[1])} | {ms(bare_steps[1])} | "
              f"{ms(steps[2])} | {ms(cpp_all)} | {ms(py_min)} | {ms(py_min - cpp_all)} | "
              f"{ms(bare_py)} |")

    print()
    print(f"Cold: the first call of a fresh process (import and volume excluded), threads {t}:")
    print("| volume | scikit-image, first call | isotile MC, first call | speed-up |")
    print("| --- | ---: | ---: | ---: |")
    for name, vol, level, load in volumes:
        sk = cold_first_call(load, level, t, True)
        mc = cold_first_call(load, level, t, False)
        print(f"| {name} | {sk * 1e3:.1f} ms | {mc * 1e3:.1f} ms | {sk / mc:.1f}x |")

    # The same work on one thread, in CPU time (time.process_time): what each side costs, whatever
    # else the machine is running (wall-clock times above grow with the load average).
    print()
    print("| volume | scikit-image, CPU s | isotile MC threads=1, CPU s | ratio | normals=False, CPU s "
          "| ratio | checks + range | extract() | values |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    cpu = time.process_time
    for name, vol, level, _ in volumes:
        sk = median_time(lambda: sk_mc(vol, level), 3, cpu)
        mc = median_time(lambda: isotile.marching_cubes(vol, level, threads=1), args.repeats, cpu)
        bare = median_time(lambda: isotile.marching_cubes(vol, level, threads=1, normals=False),
                           args.repeats, cpu)
        steps = cpu_steps(vol, level, args.repeats)
        print(f"| {name} | {sk:.3f} | {mc:.3f} | {sk / mc:.1f}x | {bare:.3f} | {sk / bare:.1f}x | "
              + " | ".join(f"{x:.3f}" for x in steps) + " |")
    if base:
        baseline_table(base, args.baseline, volumes, t, args.repeats, sk_mc)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
