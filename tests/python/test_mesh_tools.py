# isotile.quality and isotile.simplify: the same numbers and meshes as the isotile program's
# `quality --json` and `simplify` on the same mesh.
import json
import os
import warnings

import numpy as np
import pytest

import isotile
from conftest import read_ply, run_cli, sphere


@pytest.fixture
def mesh_file(tmp_path):
    vol = sphere((40, 44, 48), radius=16.0)
    raw = tmp_path / "s_48x44x40_float32.raw"
    vol.tofile(raw)
    out = tmp_path / "s.ply"
    run_cli("extract", raw, "--iso", "0.3", "--method", "macet", "-o", out)
    return out


def test_quality_is_the_program_s(mesh_file):
    p, _, f = read_ply(mesh_file)
    ours = isotile.quality(p, f, check_intersections=True)
    theirs = json.loads(run_cli("quality", mesh_file, "--json", "--check-intersections"))
    assert ours["triangles"] > 1000
    for key, value in theirs.items():
        if key == "mesh":
            continue
        assert ours[key] == value, key
    # Axis order does not change the measures (the module's vertices are (z, y, x)).
    swapped = isotile.quality(p[:, ::-1], f[:, ::-1])
    assert swapped["radius_ratio_mean"] == pytest.approx(ours["radius_ratio_mean"], rel=1e-12)
    assert swapped["euler"] == ours["euler"] and swapped["closed"]


def test_simplify_is_the_program_s(mesh_file, tmp_path):
    p, _, f = read_ply(mesh_file)
    out = tmp_path / "simple.ply"
    run_cli("simplify", mesh_file, out, "--ratio", "0.2")
    want_p, _, want_f = read_ply(out)
    for threads in (1, 2):
        v, faces = isotile.simplify(p, f, ratio=0.2, threads=threads)
        assert v.dtype == np.float32 and faces.dtype == np.int32
        assert np.array_equal(v, want_p) and np.array_equal(faces, want_f)
    v, faces = isotile.simplify(p, f, faces=500)
    assert len(faces) <= 520  # the target, within what the topology allows
    v2, f2 = isotile.simplify(p, f, max_error=0.05)
    assert 0 < len(f2) < len(f)


def test_mesh_tools_errors():
    p = np.zeros((3, 3), np.float32)
    with pytest.raises(ValueError, match="past the 3 vertices"):
        isotile.quality(p, np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match=r"vertices must be an \(N, 3\) array"):
        isotile.quality(p[:, :2], np.array([[0, 1, 2]]))
    with pytest.raises(TypeError, match="integer"):
        isotile.quality(p, np.array([[0.0, 1.0, 2.0]]))
    with pytest.raises(ValueError, match="needs ratio"):
        isotile.simplify(p, np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="ratio"):
        isotile.simplify(p, np.array([[0, 1, 2]]), ratio=1.5)
    # A negative index is not "past" the vertices.
    with pytest.raises(ValueError, match="refers to vertex -1: indices count from 0"):
        isotile.quality(p, np.array([[0, 1, -1]]))
    with pytest.raises(ValueError, match="faces row 0 refers to vertex -1: indices count from 0"):
        isotile.write_mesh("never.ply", (p, np.array([[0, 1, -1]])))
    # An unsigned index is read as given (2**64 - 1 was "vertex -1" once made int64).
    for call in (isotile.quality, isotile.simplify):
        with pytest.raises(ValueError, match="faces row 0 refers to vertex 18446744073709551615, "
                                             "past the 3 vertices"):
            call(p, np.array([[0, 1, 2**64 - 1]], np.uint64), **({"ratio": 0.5}
                                                                 if call is isotile.simplify
                                                                 else {}))
    # No faces is no faces, whatever the empty array's type (write_mesh took an empty float
    # array, quality called it not an integer array).
    assert isotile.quality(p, np.zeros((0, 3)))["triangles"] == 0


def test_quality_of_no_faces_and_nan_positions(tmp_path):
    p = np.zeros((3, 3), np.float32)
    # No face: neither closed nor open, no radius ratio (null in the CLI's JSON, None here).
    q = isotile.quality(p, np.zeros((0, 3), np.int32))
    assert q["triangles"] == 0 and q["closed"] is None and q["radius_ratio_min"] is None
    # A NaN position is written by no writer (every reader refuses it), and measured by no
    # measure (quality called the triangles degenerate and the mesh closed).
    p[1, 2] = np.nan
    with pytest.raises(ValueError, match="vertex 1 has a coordinate that is not a finite number"):
        isotile.write_mesh(tmp_path / "nan.ply", (p, np.array([[0, 1, 2]])))
    assert not (tmp_path / "nan.ply").exists()
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert isotile.quality(tet, faces)["closed"] is True
    for bad, what in ((np.nan, r"\(nan\)"), (np.inf, r"\(inf: infinite"),
                      (1e39, r"\(inf: infinite, or past float32's largest, 3.4e38\)")):
        v = tet.copy()
        v[3, 0] = bad
        for call in (lambda: isotile.quality(v, faces),
                     lambda: isotile.simplify(v, faces, ratio=0.5)):
            # With warnings made errors too: NumPy's warning of the cast of 1e39 to float32 was
            # the error raised, as "vertices must be numeric".
            with pytest.raises(ValueError, match="vertices: vertex 3 has a coordinate that is not "
                                                 "a finite number " + what):
                with warnings.catch_warnings():
                    warnings.simplefilter("error")
                    call()


def test_arrays_that_are_not_real_numbers_are_refused(tmp_path):
    # NumPy would parse strings and drop imaginary parts; normals that failed to convert were read
    # as an array (a crash), and non-finite ones were written.
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    faces = np.array([[0, 1, 2]])
    out = tmp_path / "m.ply"
    for bad, name in ((np.array([["0", "0", "1"]] * 3), "str"), (tri.astype(complex), "complex"),
                      (tri.astype(object), "object")):
        with pytest.raises(TypeError, match="vertices must be an array of real numbers, not " +
                                            name):
            isotile.quality(bad, faces)
        with pytest.raises(TypeError, match="normals must be an array of real numbers, not " +
                                            name):
            isotile.Mesh(tri, faces, None, bad).save(out)
    for bad, what in ((np.nan, r"\(nan\)"), (1e39, r"\(inf: infinite, or past float32's")):
        normals = np.zeros((3, 3))
        normals[2, 1] = bad
        with pytest.raises(ValueError, match="normals: row 2 has a value that is not a finite "
                                             "number " + what):
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                isotile.Mesh(tri, faces, None, normals).save(out)
    assert not out.exists()
    isotile.Mesh(tri, faces, None, np.array([[0, 0, 1]] * 3)).save(out)
    assert isotile.read_mesh(out).normals.tolist() == [[0, 0, 1]] * 3


def test_threads_past_the_cores_print_nothing(capfd):
    # TBB printed "The request for N workers is ignored" on stderr, past Python's warnings.
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]], np.float32)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    q = isotile.quality(p, f, threads=(os.cpu_count() or 1) + 3)
    assert q["closed"] is True
    assert capfd.readouterr().err == ""


def test_the_version_is_the_librarys():
    assert run_cli("--version") == f"isotile {isotile.__version__}\n"
    assert isotile.__version__.count(".") == 2
