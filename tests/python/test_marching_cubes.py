# isotile.marching_cubes: the same mesh as the C++ library (through the isotile program) bit for
# bit, scikit-image's conventions, every dtype and layout read in place, errors, lifetime.
import gc
import json
import os
import subprocess
import sys
import textwrap
import threading
import time
import tracemalloc

import numpy as np
import pytest

import isotile
from conftest import (bonsai, read_ply, require, run_cli, signed_volume, skip, sphere,
                      two_way_distance)

RAW_TYPES = {"int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
             "int32": np.int32, "uint32": np.uint32, "float32": np.float32,
             "float64": np.float64}


def cli_mesh(tmp_path, vol, level, *args):
    """The isotile program's mesh of `vol` (C-ordered [z, y, x], written as a raw file)."""
    name = np.dtype(vol.dtype).name
    z, y, x = vol.shape
    raw = tmp_path / f"v_{x}x{y}x{z}_{name}.raw"
    np.ascontiguousarray(vol).tofile(raw)
    out = tmp_path / "out.ply"
    run_cli("extract", raw, "--iso", repr(float(level)), "-o", out, "--normals", *args)
    return read_ply(out)


def test_same_mesh_as_the_program_bit_for_bit(tmp_path):
    base = sphere((30, 34, 38), radius=11.3, dtype=np.float64)
    for name, t in RAW_TYPES.items():
        scale = 1.0 if np.dtype(t).kind == "f" else 9.0
        vol = (base * scale + (100 if name.startswith("u") else 0)).astype(t)
        level = 100.5 if name.startswith("u") else 0.5
        verts, faces, normals, _ = isotile.marching_cubes(vol, level)
        p, n, f = cli_mesh(tmp_path, vol, level)
        assert len(f) > 1000, name
        # The module's vertices are the program's with the columns in the array's axis order.
        assert np.array_equal(verts[:, ::-1], p), name
        assert np.array_equal(normals[:, ::-1], n), name
        assert np.array_equal(faces, f), name


@pytest.mark.parametrize("method,args", [("macet", ["--method", "macet"]),
                                         ("dc", ["--method", "dc"])])
def test_other_methods_and_spacing_match_the_program(tmp_path, method, args):
    vol = sphere((24, 28, 32), radius=9.2)
    spacing = (0.7, 1.3, 2.1)  # axis 0, 1, 2 = z, y, x
    verts, faces, normals, _ = isotile.marching_cubes(vol, 0.25, spacing=spacing, method=method)
    p, n, f = cli_mesh(tmp_path, vol, 0.25, *args, "--spacing", "2.1,1.3,0.7")
    assert len(f) > 500
    assert np.array_equal(verts[:, ::-1], p)
    assert np.array_equal(normals[:, ::-1], n)
    assert np.array_equal(faces, f)


def write_ply(path, verts, faces):
    verts = np.ascontiguousarray(verts, dtype="<f4")
    rows = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    rows["n"], rows["i"] = 3, faces
    with open(path, "wb") as f:
        f.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\n"
                 "property float x\nproperty float y\nproperty float z\n"
                 f"element face {len(faces)}\nproperty list uchar int vertex_indices\n"
                 "end_header\n").encode())
        f.write(verts.tobytes())
        f.write(rows.tobytes())


def surface_distance(tmp_path, a, b):
    """The library's two-way surface distance (isotile quality --reference): (mean, max)."""
    import json
    write_ply(tmp_path / "a.ply", *a)
    write_ply(tmp_path / "b.ply", *b)
    j = json.loads(run_cli("quality", tmp_path / "a.ply", "--reference", tmp_path / "b.ply",
                           "--json"))
    return j["hausdorff_mean"], j["hausdorff_max"]


def compare_with_skimage(vol, level, spacing=(1.0, 1.0, 1.0), voxel=1.0, tmp_path=None,
                         max_distance=0.5):
    skimage = require("skimage.measure")
    from skimage.measure import marching_cubes as sk_mc
    for direction in ("descent", "ascent"):
        v, f, n, val = isotile.marching_cubes(vol, level, spacing=spacing,
                                              gradient_direction=direction)
        sv, sf, sn, sval = sk_mc(vol, level, spacing=spacing, gradient_direction=direction)
        ours, theirs = signed_volume(v, f), signed_volume(sv, sf)
        # Same orientation (sign) and enclosed volume within 1%.
        assert np.sign(ours) == np.sign(theirs) != 0, direction
        assert abs(ours - theirs) <= 0.01 * abs(theirs), (ours, theirs)
        # Same axis order and scale: the surfaces within half a voxel of each other both ways.
        if tmp_path is None:
            assert two_way_distance(v, sv) < 0.5 * voxel
        else:
            mean, worst = surface_distance(tmp_path, (v, f), (sv, sf))
            assert mean < 0.01 * voxel and worst < max_distance * voxel, (mean, worst)
        # Normals agree in direction where the vertices coincide; values as scikit-image's.
        from scipy.spatial import cKDTree
        d, i = cKDTree(sv).query(v)
        same = d < 1e-3 * voxel
        assert same.mean() > 0.9
        # scikit-image's normals are the gradient in index space, isotile's in world space (spacing
        # applied): the same where the spacing is isotropic, on the same side otherwise.
        dots = np.einsum("ij,ij->i", n[same], sn[i[same]])
        if len(set(spacing)) == 1:
            assert np.median(dots) > 0.99
        else:
            assert dots.min() > 0
        assert np.allclose(val[same], sval[i[same]], rtol=1e-5, atol=1e-5)
    return v, f


def test_sphere_against_skimage():
    v, f = compare_with_skimage(sphere(), 0.0)
    # A bright sphere: "descent" faces as scikit-image's, whose signed volume in (z, y, x) is
    # negative (the mirror of isotile's outward winding in x, y, z).
    assert signed_volume(v, f) > 0  # last call was "ascent"


def test_anisotropic_spacing_against_skimage():
    vol = sphere((30, 40, 50), radius=12.0)
    v, _ = compare_with_skimage(vol, 0.0, spacing=(2.5, 1.0, 0.5), voxel=0.5)
    extent = v.max(axis=0) - v.min(axis=0)
    assert np.allclose(extent, [2 * 12 * 2.5, 2 * 12 * 1.0, 2 * 12 * 0.5], rtol=0.05)


def test_axis_order_of_a_box():
    vol = np.zeros((10, 20, 30), np.float32)
    vol[2:5, 3:12, 4:25] = 1
    v, _, _, _ = isotile.marching_cubes(vol, 0.5, spacing=(3, 2, 1))
    assert np.allclose(v.min(axis=0), [1.5 * 3, 2.5 * 2, 3.5])
    assert np.allclose(v.max(axis=0), [4.5 * 3, 11.5 * 2, 24.5])


def test_bonsai_against_skimage(tmp_path):
    vol = bonsai()
    # Lewiner's tables resolve ambiguous cell faces by the asymptotic decider, isotile's (VTK's)
    # by a fixed rule: where they choose differently, the two surfaces are up to sqrt(1/2) voxel
    # apart (0.685 measured, over a mean of 0.0055).
    compare_with_skimage(vol, 49.5, tmp_path=tmp_path, max_distance=0.5**0.5)
    # scikit-image's "lorensen" (no decider) gives as many triangles, within half a voxel.
    from skimage.measure import marching_cubes as sk_mc
    v, f, _, _ = isotile.marching_cubes(vol, 49.5)
    sv, sf, _, _ = sk_mc(vol, 49.5, method="lorensen")
    assert len(f) == len(sf)
    assert surface_distance(tmp_path, (v, f), (sv, sf))[1] < 0.51


def every_layout(vol):
    yield "C", vol
    yield "Fortran", np.asfortranarray(vol)
    yield "sliced", np.ascontiguousarray(np.pad(vol, 3))[3:-3:1, 3:-3, 3:-3]
    yield "strided", vol[::2, :, 1:]
    yield "transposed", vol.transpose(2, 0, 1)


@pytest.mark.parametrize("dtype", ["int8", "uint8", "int16", "uint16", "int32", "uint32",
                                   "float32", "float64", "bool", "float16", "int64", "uint64",
                                   ">i2"])
def test_every_dtype_and_layout(dtype):
    base = sphere((26, 30, 34), radius=10.0)
    vol = (base > 0) if dtype == "bool" else (base * 4 + 50).astype(dtype)
    level = 0.5 if dtype == "bool" else 50.25
    copies = dtype in ("float16", "int64", "uint64", ">i2")
    for layout, v in every_layout(vol):
        want = isotile.marching_cubes(np.ascontiguousarray(v, dtype=np.float64), level)
        tracemalloc.start()
        got = isotile.marching_cubes(v, level)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        for a, b in zip(got, want):
            assert np.array_equal(a, b), (dtype, layout)
        # Read in place: no allocation the size of the volume (NumPy's are traced); the
        # documented copies make one.
        if copies:
            assert peak >= v.size * 2, (dtype, layout, peak)
        else:
            assert peak < v.size * max(v.itemsize, 1) // 2, (dtype, layout, peak)


def test_reversed_axes_are_copied_and_right():
    vol = sphere((20, 22, 24), center=(8, 9, 13), radius=6.0)
    flipped = vol[::-1]
    got = isotile.marching_cubes(flipped, 0.0)
    want = isotile.marching_cubes(np.ascontiguousarray(flipped), 0.0)
    for a, b in zip(got, want):
        assert np.array_equal(a, b)


def test_outputs_own_the_library_buffers_and_outlive_everything():
    vol = sphere()
    verts, faces, normals, values = isotile.marching_cubes(vol, 0.0)
    keep = [a.copy() for a in (verts, faces, normals, values)]
    assert not verts.flags.owndata and verts.base is not None
    del vol
    for _ in range(3):
        gc.collect()
    # Churn the allocator, so that freed buffers would be overwritten.
    junk = [isotile.marching_cubes(sphere(radius=r), 0.0) for r in (8.0, 11.0, 14.0)]
    del junk
    gc.collect()
    for a, b in zip((verts, faces, normals, values), keep):
        assert np.array_equal(a, b)
    faces_only = faces
    del verts, normals, values
    gc.collect()
    assert np.array_equal(faces_only, keep[1])


def test_no_leak_over_many_calls():
    vol = sphere((64, 64, 64), radius=25.0)
    def rss():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    for _ in range(5):
        isotile.marching_cubes(vol, 0.0)
    gc.collect()
    before = rss()
    for _ in range(40):
        isotile.marching_cubes(vol, 0.0)
    gc.collect()
    # Each mesh holds about 1 MB: forty leaked ones would show.
    assert rss() - before < 16 << 20


def test_errors_match_skimage():
    require("skimage.measure")
    from skimage.measure import marching_cubes as sk_mc
    vol = sphere((10, 10, 10), radius=3.0)
    # The range is the whole volume's, whatever the step: 7 is in it, but not in vol[::2, ::2, ::2].
    odd = np.zeros((9, 9, 9), np.float32)
    odd[1, 1, 1] = 10
    cases = [
        (lambda f: f(odd, 7.0, step_size=2), RuntimeError),
        (lambda f: f(vol[0], 0.0), ValueError),              # 2-D
        (lambda f: f(vol[None], 0.0), ValueError),           # 4-D
        (lambda f: f(np.zeros((0, 4, 4), np.float32), 0.0), ValueError),   # empty
        (lambda f: f(np.zeros((1, 4, 4), np.float32), 0.0), ValueError),   # too thin
        (lambda f: f(vol, 100.0), ValueError),               # level above the range
        (lambda f: f(vol, -100.0), ValueError),              # level below
        (lambda f: f(np.zeros((4, 4, 4), np.float32), 0.0), RuntimeError),  # no surface
        (lambda f: f(vol, 0.0, gradient_direction="up"), ValueError),
        (lambda f: f(vol, 0.0, step_size=0), ValueError),
        (lambda f: f(vol, 0.0, spacing=(1, 1)), ValueError),
        (lambda f: f(vol, 0.0, step_size=10), RuntimeError),  # one sample per axis: no cell
        (lambda f: f(vol, 0.0, method="fast"), ValueError),
        (lambda f: f(vol, 0.0, mask=np.ones((9, 10, 10), bool)), ValueError),
    ]
    for call, error in cases:
        with pytest.raises(error) as ours:
            call(isotile.marching_cubes)
        with pytest.raises(error) as theirs:
            call(sk_mc)
        assert str(ours.value)


def test_errors_of_isotile_own():
    vol = sphere((10, 10, 10), radius=3.0)
    # Said in its own words where scikit-image's are a NameError, a TypeError or "no surface".
    for bad in ("abc", 5, (1, "x", 1)):
        with pytest.raises(ValueError, match="^`spacing` must consist of three floats"):
            isotile.marching_cubes(vol, 0.0, spacing=bad)
    with pytest.raises(RuntimeError, match="step_size 10 leaves fewer than 2 samples along an axis"):
        isotile.marching_cubes(vol, 0.0, step_size=10)
    with pytest.raises(ValueError, match="^simplify is the fraction of faces to keep"):
        isotile.extract(vol, 0.0, simplify=True)
    with pytest.raises(ValueError, match="NaN"):
        isotile.marching_cubes(vol, float("nan"))
    bad = vol.copy()
    bad[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match=r"NaN or Inf \(first at x=3, y=2, z=1\)"):
        isotile.marching_cubes(bad, 0.0)
    # Finite float64 samples whose differences overflow (vertices snapped onto samples, NaN
    # normals) are refused as NaN is; 1e100 is the largest taken, and gives unit normals.
    big = np.where(sphere((8, 9, 10), radius=3.0) > 0, 9e307, -9e307)
    with pytest.raises(ValueError, match=r"samples are past \+-1e100 \(first at x=0, y=0, z=0\)"):
        isotile.marching_cubes(big, 0.0)
    with pytest.raises(ValueError, match=r"past \+-1e100"):
        isotile.extract(big, 0.0)
    _, _, n, _ = isotile.marching_cubes(np.sign(big) * 1e100, 0.0)
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-6)
    with pytest.raises(TypeError):
        isotile.marching_cubes(vol.astype(np.complex64), 0.0)
    with pytest.raises(ValueError, match="threads"):
        isotile.marching_cubes(vol, 0.0, threads=0)
    # scikit-image takes these and returns a flat, an inside-out or a non-finite mesh.
    for spacing in [(0, 1, 1), (1, -1, 1), (1, 1, np.nan), (np.inf, 1, 1)]:
        with pytest.raises(ValueError, match="`spacing` must be finite and positive"):
            isotile.marching_cubes(vol, 0.0, spacing=spacing)
    # isotile's float32 vertices cannot hold this grid (scikit-image's come back as float64).
    with pytest.raises(ValueError, match="beyond the largest float32"):
        isotile.marching_cubes(vol, 0.0, spacing=(1e38, 1, 1))
    with pytest.raises(ValueError, match="backend"):
        isotile.marching_cubes(vol, 0.0, backend="cuda")
    with pytest.raises(ValueError, match="quality"):
        isotile.marching_cubes(vol, 0.0, method="macet", quality="best")
    with pytest.raises(ValueError, match="Input volume should be a 3D numpy array"):
        isotile.marching_cubes([[[0, 1], [0, 1]], [[0, 1], [0, 1]]], 0.5)


def test_level_none_is_the_middle_of_the_range():
    vol = sphere((20, 20, 20), radius=7.0)
    mid = 0.5 * (float(vol.min()) + float(vol.max()))
    for a, b in zip(isotile.marching_cubes(vol), isotile.marching_cubes(vol, mid)):
        assert np.array_equal(a, b)


def test_threads_do_not_change_the_result():
    vol = sphere((60, 64, 68), radius=24.0)
    one = isotile.marching_cubes(vol, 0.0, threads=1)
    for t in (2, 3, None):
        for a, b in zip(isotile.marching_cubes(vol, 0.0, threads=t), one):
            assert np.array_equal(a, b)


def test_allow_degenerate_false_drops_the_triangles_that_repeat_a_point():
    # Integer samples at an integer level: samples equal to it put several crossings on one
    # point, and the triangles between them have no area.
    vol = np.random.default_rng(3).integers(0, 4, (12, 13, 14)).astype(np.float32)
    v, f, n, val = isotile.marching_cubes(vol, 2)
    kv, kf, kn, kval = isotile.marching_cubes(vol, 2, allow_degenerate=False)

    def corners(verts, faces):
        return verts[faces]

    def repeats(p):
        return (np.all(p[:, 0] == p[:, 1], 1) | np.all(p[:, 1] == p[:, 2], 1)
                | np.all(p[:, 0] == p[:, 2], 1))

    p, kp = corners(v, f), corners(kv, kf)
    assert repeats(p).sum() > 100 and not repeats(kp).any()
    # The same triangles otherwise, corner for corner, in the same order.
    assert np.array_equal(kp, p[~repeats(p)])
    # One vertex per point, each used, its normal and value those of a vertex at that point.
    assert len(np.unique(kv, axis=0)) == len(kv) and np.array_equal(np.unique(kf), np.arange(len(kv)))
    first = {tuple(x): i for i, x in reversed(list(enumerate(v)))}
    at = np.array([first[tuple(x)] for x in kv])
    assert np.array_equal(kn, n[at]) and np.array_equal(kval, val[at])
    assert kf.dtype == f.dtype
    # Nothing left: no surface, as when there was none (empty arrays came back). At the data's
    # largest value only the samples equal to it are inside, and the surface round each is a
    # point.
    one = np.zeros((4, 4, 4), np.float32)
    one[1, 1, 1] = 1
    assert len(isotile.marching_cubes(one, 1.0)[1]) == 8
    with pytest.raises(isotile.NoSurface, match="every triangle has two corners at one point"):
        isotile.marching_cubes(one, 1.0, allow_degenerate=False)
    # Dual Contouring on one cell: a surface Marching Cubes finds, no face; the message says why.
    cell = np.zeros((2, 2, 2), np.float32)
    cell[0, 0, 0] = 1
    assert len(isotile.marching_cubes(cell, 0.5)[1]) == 1
    with pytest.raises(isotile.NoSurface, match="meets only the array's border"):
        isotile.marching_cubes(cell, 0.5, method="dc")
    # Nothing to drop: the mesh is unchanged.
    s = sphere((20, 21, 22), radius=7.3)
    a, b = isotile.marching_cubes(s, 0.5), isotile.marching_cubes(s, 0.5, allow_degenerate=False)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))


def test_step_size_is_a_strided_view():
    vol = sphere((41, 45, 49), radius=15.0)
    a = isotile.marching_cubes(vol, 0.0, step_size=2, spacing=(1.5, 1, 1))
    b = isotile.marching_cubes(np.ascontiguousarray(vol[::2, ::2, ::2]), 0.0, spacing=(3, 2, 2))
    for x, y in zip(a, b):
        assert np.array_equal(x, y)
    require("skimage.measure")
    from skimage.measure import marching_cubes as sk_mc
    sv, sf, _, _ = sk_mc(vol, 0.0, step_size=2, spacing=(1.5, 1, 1))
    assert abs(signed_volume(a[0], a[1]) - signed_volume(sv, sf)) < 0.01 * abs(signed_volume(sv, sf))


def test_mask_keeps_the_cells_inside_it():
    vol = sphere((30, 30, 30), radius=11.0)
    full = isotile.marching_cubes(vol, 0.0)
    everywhere = isotile.marching_cubes(vol, 0.0, mask=np.ones(vol.shape, bool))
    for a, b in zip(full, everywhere):
        assert np.array_equal(a, b)
    mask = np.zeros(vol.shape, bool)
    mask[:, :, :16] = True  # cells with x in 0..14 have all eight corners inside
    v, f, n, val = isotile.marching_cubes(vol, 0.0, mask=mask)
    assert 0 < len(f) < len(full[1])
    # The kept triangles are exactly the full mesh's triangles in those cells, same positions.
    def triangles(verts, faces):
        return {tuple(sorted(map(tuple, verts[t]))) for t in faces}
    centroid_x = full[0][full[1]].mean(axis=1)[:, 2]
    want = triangles(full[0], full[1][np.floor(centroid_x) <= 14])
    assert triangles(v, f) == want
    # No vertex left unused.
    assert len(np.unique(f)) == len(v)


def test_mask_values_come_from_the_cells_inside_it():
    """values, with a mask: the largest range of the cells inside the mask around each vertex,
    as scikit-image gives them (a masked-out cell neighbouring a kept vertex does not count)."""
    require("skimage.measure")
    from skimage.measure import marching_cubes as sk_mc
    rng = np.random.default_rng(3)
    vol = sphere((24, 24, 24), radius=8.0) + rng.normal(0, 0.3, (24, 24, 24)).astype(np.float32)
    mask = np.zeros(vol.shape, bool)
    mask[:13] = True
    got = isotile.marching_cubes(vol, 0.0, mask=mask)
    want = sk_mc(vol, 0.0, mask=mask)
    mine = {tuple(v): x for v, x in zip(np.round(got[0], 4), got[3])}
    theirs = {tuple(v): x for v, x in zip(np.round(want[0], 4), want[3])}
    shared = set(mine) & set(theirs)
    assert len(shared) > 100
    on_border = [v for v in shared if v[0] == 12.0]
    assert on_border, "no vertex on the mask's border plane"
    assert all(mine[v] == pytest.approx(theirs[v], rel=1e-6, abs=1e-6) for v in shared)


def test_unaligned_arrays_are_copied():
    """An array whose data is not aligned for its type (a buffer at an odd offset, a memmap
    after a header) is copied, as the docs say, not refused."""
    vol = sphere((16, 16, 16), radius=5.0)
    raw = np.frombuffer(b"\0" + vol.tobytes(), dtype=np.float32, offset=1).reshape(vol.shape)
    assert not raw.flags.aligned and raw.flags.c_contiguous
    for a, b in zip(isotile.marching_cubes(raw, 0.0), isotile.marching_cubes(vol, 0.0)):
        assert np.array_equal(a, b)
    assert np.array_equal(isotile.extract(raw, 0.0).faces, isotile.extract(vol, 0.0).faces)


def test_gil_is_released_during_the_work():
    vol = sphere((200, 200, 200), radius=80.0)
    counts = []
    done = threading.Event()
    def worker():
        isotile.marching_cubes(vol, 0.0, threads=1)
        done.set()
    t = threading.Thread(target=worker)
    start = time.perf_counter()
    t.start()
    n = 0
    while not done.is_set():
        n += 1
    t.join()
    elapsed = time.perf_counter() - start
    # The main thread kept running Python while the extraction ran (with the GIL held, it would
    # have waited for the whole call).
    assert elapsed > 0.02
    assert n > 10000, (n, elapsed)


@pytest.mark.parametrize("method", ["mc", "macet", "dc"])
def test_gl_backends_give_the_cpu_mesh(method):
    vol = sphere((30, 34, 38), radius=12.0)
    cpu = isotile.marching_cubes(vol, 0.0, method=method)
    for backend, why in isotile.backends().items():
        if backend == "cpu":
            continue
        if why:
            # The library's reason, as the exception's message.
            with pytest.raises(ValueError) as e:
                isotile.marching_cubes(vol, 0.0, method=method, backend=backend)
            assert str(e.value)
            skip("gl", f"backend {backend} unavailable: {why}")
        got = isotile.marching_cubes(vol, 0.0, method=method, backend=backend)
        for a, b in zip(got, cpu):
            assert np.array_equal(a, b), (backend, method)


def require_hp():
    why = isotile.backends().get("hp")
    if why:
        skip("gl", f"backend hp unavailable: {why}")


# The start of the scripts the GL tests run in a process of their own: `ball(shape, radius)`, a
# ball of float32 samples (positive inside) centred in `shape`.
SCRIPT_HEAD = """\
import numpy as np
import isotile
def ball(shape, radius):
    z, y, x = np.indices(shape, dtype=np.float64)
    c = [(n - 1) / 2 for n in shape]
    return (radius - np.sqrt((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2)).astype("f4")
"""


def run_script(path, body, env=None):
    """Writes SCRIPT_HEAD and `body` to `path` and runs it with this Python, within 120 s."""
    path.write_text(SCRIPT_HEAD + textwrap.dedent(body))
    return subprocess.run([sys.executable, str(path)], env=env, capture_output=True, text=True,
                          timeout=120)


def test_a_gl_failure_under_auto_is_a_warning_and_the_cpus_mesh(tmp_path):
    """Under backend="auto" a GL backend that fails is followed by the CPU: one RuntimeWarning at
    the caller's line (one line: the driver's log joined), nothing on stderr, the CPU's mesh.
    Mesa is made to offer OpenGL 4.5 but accept no GLSL newer than 1.40, so the HistoPyramid's
    first program fails; in a process of its own, as the GL context is made once per process."""
    require_hp()
    script = tmp_path / "fallback.py"
    env = dict(os.environ, ISOTILE_AUTO_BACKEND="hp", ISOTILE_PROGRAM_CACHE="off",
               MESA_GL_VERSION_OVERRIDE="4.5", MESA_GLSL_VERSION_OVERRIDE="140")
    r = run_script(script, """
        import json, warnings
        vol = ball((20, 22, 24), 8.0)
        cpu = isotile.marching_cubes(vol, 0.0)
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            got = isotile.marching_cubes(vol, 0.0, backend="auto")
        print(json.dumps({"same": all(np.array_equal(a, b) for a, b in zip(got, cpu)),
                          "said": [[w.category.__name__, str(w.message), w.filename]
                                   for w in said]}))
        """, env)
    assert r.returncode == 0, r.stderr
    assert "isotile: warning" not in r.stderr, r.stderr
    out = json.loads(r.stdout)
    assert out["same"]
    if not out["said"]:
        skip("gl", "the GL driver ignores MESA_GLSL_VERSION_OVERRIDE: hp did not fail")
    assert len(out["said"]) == 1, out["said"]
    category, message, filename = out["said"][0]
    assert category == "RuntimeWarning"
    assert message.startswith("the hp backend failed ("), message
    assert message.endswith("); extracting on the CPU instead"), message
    assert "\n" not in message, message
    assert filename == str(script)


def test_threads_beyond_what_tbb_starts_are_refused():
    # TBB crashed tearing down an arena of 100,000 threads (quality, simplify, marching_cubes)
    # and ran out of memory at 2**31 - 1 (extract): the CLI's bound, named.
    vol = sphere((10, 10, 10), radius=3.0)
    v, f, _, _ = isotile.marching_cubes(vol, 0.0)
    for call in (lambda t: isotile.marching_cubes(vol, 0.0, threads=t),
                 lambda t: isotile.quality(v, f, threads=t),
                 lambda t: isotile.simplify(v, f, ratio=0.5, threads=t),
                 lambda t: isotile.extract(vol, 0.0, threads=t)):
        for t in (4097, 100000, 2**31 - 1, 2**31):
            with pytest.raises(ValueError, match="threads must be an int from 1 to 4096"):
                call(t)
    assert len(isotile.marching_cubes(vol, 0.0, threads=4096)[1]) == len(f)


def test_bool_samples_are_what_numpy_says():
    # A uint8 array viewed as bool holds 2s: NumPy reads them as True, and so must the mesh.
    z, y, x = np.indices((10, 11, 12))
    inside = (z - 4.5) ** 2 + (y - 5.0) ** 2 + (x - 5.5) ** 2 < 9
    twos = (inside.astype(np.uint8) * 2).view(np.bool_)
    assert np.array_equal(twos, inside)
    for a, b in zip(isotile.marching_cubes(twos, 0.5), isotile.marching_cubes(inside, 0.5)):
        assert np.array_equal(a, b)
    assert np.array_equal(isotile.extract(twos[:, ::-1], 0.5).vertices,
                          isotile.extract(inside[:, ::-1], 0.5).vertices)
    with pytest.raises(ValueError, match="Surface level must be within volume data range"):
        isotile.marching_cubes(twos, 1.5)


def test_gl_runs_report_progress_while_other_threads_ask_for_the_backends(tmp_path):
    """A GL run's progress callback is called on the GL context's own thread (docs/gl.md) and takes
    the GIL there, while the run's caller holds the GL context's lock; a thread that asks for
    isotile.backends() (which needs that lock) must not hold the GIL while it waits, or neither
    goes on. In a process of its own with a time limit, so that a deadlock fails the test."""
    require_hp()
    r = run_script(tmp_path / "progress_and_backends.py", """
        import threading
        vol = ball((40, 40, 40), 15.0)
        cpu = isotile.extract(vol, 0.0, backend="cpu").vertices
        stop = threading.Event()
        asked = [0]
        def ask():
            while not stop.is_set():
                isotile.backends()
                asked[0] += 1
        t = threading.Thread(target=ask)
        t.start()
        calls = [0]
        def progress(stage, brick, bricks, fraction):
            calls[0] += 1
            return True
        same = all(np.array_equal(isotile.extract(vol, 0.0, backend="hp",
                                                  progress=progress).vertices, cpu)
                   for _ in range(10))
        stop.set()
        t.join()
        print(same, calls[0] > 0, asked[0] > 0)
        """)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True", "True", "True"], r.stdout


def test_a_gl_run_leaves_nothing_alive_at_exit(tmp_path):
    """The module ends the GL context a run made when the interpreter exits (gl::shutdown(), as
    the CLI does): no EGL context or display, GL program, buffer or framebuffer is left to the
    drivers' exit handlers, which crashed NVIDIA's libEGL at exit (docs/gl.md).
    tests/gl_exit_check.c, preloaded, counts them after everything else at exit."""
    require_hp()
    check = os.environ.get("ISOTILE_GL_EXIT_CHECK")
    if not check:
        skip("gl", "ISOTILE_GL_EXIT_CHECK (tests/gl_exit_check.c, built with the GL tests) unset")
    r = run_script(tmp_path / "exit.py", """
        for backend in ("hp", "gs"):
            isotile.marching_cubes(ball((20, 22, 24), 8.0), 0.0, backend=backend)
        print("done")
        """, dict(os.environ, LD_PRELOAD=check))
    assert r.returncode == 0, r.stderr
    assert r.stdout == "done\n"
    assert "gl_exit_check: nothing alive at exit: 0 EGL contexts (of 1 made)" in r.stderr, r.stderr
