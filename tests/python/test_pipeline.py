# isotile.extract, read_volume, read_mesh and write_mesh: the library's pipeline, the same run as
# `isotile extract`. The mesh files and the stats must be the CLI's byte for byte (the stats
# without their timing and memory keys, as the CLI's own tests compare them); a Volume read first
# gives the path's mesh; progress, cancel and Ctrl-C stop a run and leave no file. Small volumes
# (fields, files the tests write), so that the suite stays fast.
import json
import os
import pathlib
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest

import isotile
from conftest import cli, skip

# Keys that differ between two runs of the same extraction (the CLI's tests leave them out too).
VOLATILE = ("seconds", "peak_rss_mb")


def steady(stats):
    return {k: v for k, v in stats.items() if k not in VOLATILE}


def write_ball(path, dtype=np.uint8, shape=(30, 34, 38)):
    """A bright ball in a raw file named as the CLI parses it (NAME_XxYxZ_TYPE.raw)."""
    z, y, x = np.indices(shape)
    d = np.sqrt((x - 18.3) ** 2 + (y - 16.1) ** 2 + (z - 14.2) ** 2)
    samples = np.clip(200 - d * 12, 0, 255).astype(dtype)
    name = f"ball_{shape[2]}x{shape[1]}x{shape[0]}_{np.dtype(dtype).name}.raw"
    samples.tofile(path / name)
    return path / name, samples


def run_cli_in(folder, *args):
    folder.mkdir(exist_ok=True)
    r = subprocess.run([cli(), "-q", "extract", *map(str, args)], cwd=folder,
                       capture_output=True, text=True)
    return r


@pytest.fixture
def ball(tmp_path):
    return write_ball(tmp_path)[0]


# The CLI and extract() on the same input, in two folders with the same relative output name.
CASES = [
    ("field:sphere:32", {}, []),
    ("field:gyroid:36", {"method": "dc", "normals": True}, ["--method", "dc", "--normals"]),
    ("field:torus:32", {"method": "macet", "quality": "max"}, ["--method", "macet",
                                                              "--quality", "max"]),
    ("field:gyroid:32", {"simplify": 0.4}, ["--simplify", "0.4"]),
    ("field:csg-box:24", {"method": "dc", "quads": True, "dc_vertices": "cell"},
     ["--method", "dc", "--quads", "--dc-vertices", "cell"]),
    ("field:sphere:24", {"frame": "grid", "check_intersections": True},
     ["--frame", "grid", "--check-intersections"]),
]


@pytest.mark.parametrize("source,options,flags", CASES)
@pytest.mark.parametrize("name", ["mesh.ply", "mesh.obj"])
def test_extract_matches_the_cli(tmp_path, monkeypatch, source, options, flags, name):
    r = run_cli_in(tmp_path / "cli", source, "-o", name, "--stats", "stats.json", *flags)
    assert r.returncode == 0, r.stderr
    (tmp_path / "py").mkdir()
    monkeypatch.chdir(tmp_path / "py")
    mesh = isotile.extract(source, output=name, **options)
    assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
    cli_stats = json.loads((tmp_path / "cli" / "stats.json").read_text())
    assert steady(mesh.stats) == steady(cli_stats)
    # save() writes what the run wrote.
    mesh.save("saved_" + name)
    saved = (tmp_path / "py" / ("saved_" + name)).read_bytes()
    assert saved == (tmp_path / "py" / name).read_bytes()


def test_an_arrays_spacing_and_origin_take_the_clis_text_too():
    # As for a path: "x,y,z" gives the tuple's mesh.
    samples = np.zeros((6, 7, 8), np.float32)
    samples[1:5, 2:5, 2:6] = 1
    text = isotile.extract(samples, 0.5, spacing="0.5,1,2", origin="-1,0,3.25")
    tuple_ = isotile.extract(samples, 0.5, spacing=(0.5, 1, 2), origin=(-1, 0, 3.25))
    plain = isotile.extract(samples, 0.5)
    assert np.array_equal(text.vertices, tuple_.vertices)
    assert not np.array_equal(text.vertices, plain.vertices)


def test_faces_and_quads_share_one_index_type(tmp_path):
    # Indices are int32 (as scikit-image gives faces) for quads too, whether the mesh comes from
    # extract, has no quads, or is read back from a file.
    quads = isotile.extract("field:csg-box:16", method="dc", quads=True)
    plain = isotile.extract("field:sphere:16")
    quads.save(tmp_path / "q.ply")
    read = isotile.read_mesh(tmp_path / "q.ply")
    for mesh in (quads, plain, read):
        assert mesh.faces.dtype == np.int32 and mesh.quads.dtype == np.int32, mesh
    assert len(quads.quads) > 0 and np.array_equal(read.quads, quads.quads)
    assert isotile.Mesh(plain.vertices, plain.faces).quads.dtype == np.int32


def test_a_file_and_iso_auto_match_the_cli(tmp_path, monkeypatch, ball):
    for iso, flags in ((100.5, ["--iso", "100.5", "--method", "dc"]), ("auto", ["--iso", "auto"])):
        r = run_cli_in(tmp_path / "cli", ball, "-o", "m.ply", "--stats", "s.json", *flags)
        assert r.returncode == 0, r.stderr
        monkeypatch.chdir(tmp_path)
        mesh = isotile.extract(ball, iso, method="dc" if iso != "auto" else "mc")
        mesh.save(tmp_path / "py.ply")
        assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli" / "m.ply").read_bytes()
        want = steady(json.loads((tmp_path / "cli" / "s.json").read_text()))
        got = steady(mesh.stats)
        assert got.pop("output") is None  # no output file asked for
        want.pop("output")
        assert got == want
    assert mesh.stats["iso_auto"]["rule"] == "otsu"


def test_a_volume_read_first_gives_the_paths_mesh(tmp_path, ball):
    volume = isotile.read_volume(ball)
    z, y, x = volume.samples.shape
    assert (x, y, z) == (38, 34, 30)
    assert volume.samples.dtype == np.uint8 and not volume.samples.flags.writeable
    assert np.array_equal(volume.samples, write_ball(tmp_path / "..", np.uint8)[1])
    for options in ({"iso": 90}, {"iso": "auto", "method": "macet"}, {"iso": 120, "method": "dc"}):
        a = isotile.extract(volume, **options)
        b = isotile.extract(ball, **options)
        for key in ("vertices", "faces", "quads"):
            assert np.array_equal(getattr(a, key), getattr(b, key)), key
        a.save(tmp_path / "a.ply")
        b.save(tmp_path / "b.ply")
        assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()
        assert steady(a.stats) == steady(b.stats)
    # An array with the volume's geometry gives the same mesh (only the name differs).
    c = isotile.extract(np.array(volume.samples), 90, spacing=volume.spacing,
                        origin=volume.origin)
    d = isotile.extract(volume, 90)
    assert np.array_equal(c.vertices, d.vertices) and np.array_equal(c.faces, d.faces)
    assert c.stats["input"] == "array" and d.stats["input"] == str(ball)
    # Samples put in the file's place are not what the run would read: refused, as a changed
    # spacing is (they were ignored: the file's mesh came back).
    volume.samples = np.zeros((2, 2, 2), np.uint8)
    with pytest.raises(ValueError, match="samples were replaced after read_volume"):
        isotile.extract(volume, 90)
    # Its direction set again as an array, the same or another: compared as numbers (NumPy
    # said "the truth value of an array ... is ambiguous").
    again = isotile.read_volume(ball)
    again.direction = np.eye(3)
    assert np.array_equal(isotile.extract(again, 90).faces, d.faces)
    again.direction = np.diag([1.0, -1.0, -1.0])
    with pytest.raises(ValueError, match="spacing, origin or direction was changed"):
        isotile.extract(again, 90)


def test_raw_options_are_the_clis(tmp_path):
    samples = write_ball(tmp_path)[1]
    plain = tmp_path / "plain.dat"
    samples.astype(">u2").tofile(plain)
    v = isotile.read_volume(plain, dims=(38, 34, 30), type="uint16", endian="big",
                            spacing=(0.5, 1.0, 2.0))
    assert v.spacing == (0.5, 1.0, 2.0)
    assert np.array_equal(v.samples, samples.astype(np.uint16))
    m = isotile.extract(plain, 100, dims="38,34,30", type="uint16", endian="big",
                        spacing="0.5,1,2")
    r = run_cli_in(tmp_path / "cli", plain, "--dims", "38,34,30", "--type", "uint16", "--endian",
                   "big", "--spacing", "0.5,1,2", "--iso", "100", "-o", "m.ply")
    assert r.returncode == 0, r.stderr
    m.save(tmp_path / "py.ply")
    assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli" / "m.ply").read_bytes()
    with pytest.raises(ValueError, match="dims must be three comma-separated numbers"):
        isotile.read_volume(plain, dims=(38, 34), type="uint16")
    # Sample counts are integers: 38.0 is named as not one (it was "not three numbers").
    with pytest.raises(ValueError, match=r"dims must be three integers .*, got \(38.0, 34, 30\)"):
        isotile.read_volume(plain, dims=(38.0, 34, 30), type="uint16")
    # NumPy's integers and floats are numbers like Python's: under NumPy 2 a float64's repr is
    # "np.float64(0.5)", which went into the text the options are parsed from.
    class Float64(float):
        def __repr__(self):
            return f"np.float64({float(self)})"
    w = isotile.read_volume(plain, dims=np.array([38, 34, 30]), type="uint16", endian="big",
                            spacing=(Float64(0.5), Float64(1.0), Float64(2.0)))
    assert w.spacing == (0.5, 1.0, 2.0) and np.array_equal(w.samples, v.samples)


@pytest.mark.parametrize("flags,options", [
    ([], {}),
    (["--method", "macet"], {"method": "macet"}),
    (["--simplify", "0.5"], {"simplify": 0.5}),
])
def test_out_of_core_matches_the_cli(tmp_path, monkeypatch, ball, flags, options):
    for source, iso in ((ball, ["--iso", "auto"]), ("field:gyroid:48", [])):
        r = run_cli_in(tmp_path / "cli", source, *iso, "--memory", "300KiB", "-o", "m.ply",
                       "--stats", "s.json", *flags)
        assert r.returncode == 0, r.stderr
        (tmp_path / "py").mkdir(exist_ok=True)
        monkeypatch.chdir(tmp_path / "py")
        stats = isotile.extract(source, "auto" if iso else None, memory="300KiB",
                                output="m.ply", **options)
        assert stats["bricks"] > 1
        assert (tmp_path / "py" / "m.ply").read_bytes() == (tmp_path / "cli" / "m.ply").read_bytes()
        assert steady(stats) == steady(json.loads((tmp_path / "cli" / "s.json").read_text()))


def test_out_of_core_gives_the_in_core_file(tmp_path):
    isotile.extract("field:gyroid:48", memory=300 * 1024, output=tmp_path / "ooc.ply")
    isotile.extract("field:gyroid:48", output=tmp_path / "in.ply", stats=False)
    assert (tmp_path / "ooc.ply").read_bytes() == (tmp_path / "in.ply").read_bytes()


def test_errors_are_the_clis_in_keywords(tmp_path, ball):
    # The CLI's checks and messages, its options named as the keywords that say the same.
    with pytest.raises(ValueError, match="^iso is required for a volume file"):
        isotile.extract(ball)
    with pytest.raises(ValueError, match="no pair of samples|range"):
        isotile.extract(ball, 300)
    assert isotile.extract(ball, 300, allow_empty=True).faces.shape == (0, 3)
    with pytest.raises(ValueError, match="streams the mesh into a file"):
        isotile.extract(ball, 100, memory="1MiB")
    with pytest.raises(ValueError, match="^macet_relax applies to method=\"macet\" only$"):
        isotile.extract(ball, 100, macet_relax=0.2)
    # Another method's options are refused, not dropped.
    with pytest.raises(ValueError, match="^quads applies to method=\"dc\" only$"):
        isotile.extract(ball, 100, quads=True)
    with pytest.raises(ValueError, match="^dc_solver applies to method=\"dc\" only$"):
        isotile.extract(ball, 100, method="macet", dc_solver="qef")
    with pytest.raises(ValueError, match="^quality applies to method=\"macet\" only$"):
        isotile.extract(ball, 100, method="dc", quality="max")
    # Empty texts are not None: they would run in core or write nothing.
    with pytest.raises(ValueError, match="memory must not be empty"):
        isotile.extract(ball, 100, memory="", output=tmp_path / "e.ply")
    with pytest.raises(ValueError, match="output must not be empty"):
        isotile.extract(ball, 100, output="")
    for key in ("spacing", "origin", "dims", "type", "series"):
        with pytest.raises(ValueError, match=f"^{key} must not be empty"):
            isotile.extract(ball, 100, **{key: ""})
        with pytest.raises(ValueError, match=f"^{key} must not be empty"):
            isotile.read_volume(ball, **{key: ""})
    for key in ("spacing", "origin"):
        with pytest.raises(ValueError, match=f"^{key} must not be empty"):
            isotile.extract(np.zeros((4, 4, 4), np.float32), 0.5, **{key: ""})
    # STL has no text form isotile writes: refused before the run, nothing written.
    with pytest.raises(ValueError, match="STL is written binary only"):
        isotile.extract(ball, 100, output=tmp_path / "a.stl", ascii=True)
    assert not (tmp_path / "a.stl").exists()
    with pytest.raises(ValueError, match="STL is written binary only"):
        isotile.write_mesh(tmp_path / "w.stl", isotile.extract(ball, 100), ascii=True)
    with pytest.raises(ValueError, match="method must be"):
        isotile.extract(ball, 100, method="marching")
    with pytest.raises(ValueError, match="iso must be a number or 'auto'"):
        isotile.extract(ball, "otsu")
    # Values of the wrong kind name their option (not pybind11's "Unable to cast").
    with pytest.raises(ValueError, match="memory must be a byte count .* not -1"):
        isotile.extract("field:sphere:16", memory=-1, output="never.ply")
    with pytest.raises(ValueError, match="spacing must be three numbers, not 2"):
        isotile.extract(np.zeros((4, 4, 4), np.float32), 0.5, spacing=2)
    with pytest.raises(ValueError, match="spacing must be three comma-separated numbers, got '1,2'"):
        isotile.extract(np.zeros((4, 4, 4), np.float32), 0.5, spacing="1,2")
    with pytest.raises(ValueError, match="simplify must be a number"):
        isotile.extract("field:sphere:16", simplify="half")
    with pytest.raises(ValueError, match="^simplify gives triangles; drop quads$"):
        isotile.extract("field:sphere:16", method="dc", quads=True, simplify=0.5)
    with pytest.raises(OSError):
        isotile.extract(tmp_path / "missing.nrrd", 1)
    with pytest.raises(ValueError):
        isotile.extract(ball, 100, output=tmp_path / "mesh.xyz")
    assert not (tmp_path / "mesh.xyz").exists()
    # No surface: the ways out as keywords.
    with pytest.raises(ValueError, match='or iso="auto" \\(or allow_empty=True to write'):
        isotile.extract(ball, 300)
    # A path and a shell command keep their dashes.
    (tmp_path / "--scans").mkdir()
    (tmp_path / "--scans" / "ct.raw").write_bytes(b"abc")
    with pytest.raises(ValueError, match="/--scans/ct.raw: the dims and sample type are unknown"):
        isotile.read_volume(tmp_path / "--scans" / "ct.raw")
    with pytest.raises(ValueError, match="`isotile quality --check-intersections`"):
        isotile.extract("field:sphere:16", memory="1MiB", output=tmp_path / "c.ply",
                        check_intersections=True)
    # One type for "no surface" from extract and marching_cubes, caught as either's.
    with pytest.raises(RuntimeError, match="no surface at iso 300"):
        isotile.extract(ball, 300)
    with pytest.raises(isotile.NoSurface):
        isotile.marching_cubes(np.zeros((2, 2, 2)), 0.0)
    assert issubclass(isotile.NoSurface, ValueError) and issubclass(isotile.NoSurface, RuntimeError)


def test_keywords_the_source_has_no_use_for_are_refused(tmp_path, ball):
    array = np.zeros((4, 4, 4), np.float32)
    array[1:3, 1:3, 1:3] = 1
    # An array has no file to say how it is stored, and no `isotile info` to run on.
    with pytest.raises(ValueError, match="^dims, endian apply only to files"):
        isotile.extract(array, 0.5, dims=(4, 4, 4), endian="big")
    with pytest.raises(ValueError, match="^iso is required: a number, or 'auto'"):
        isotile.extract(array)
    # A file says its own direction.
    with pytest.raises(ValueError, match="^direction applies only to an array"):
        isotile.extract(ball, 100, direction=np.eye(3))
    # A Volume has its own geometry, from its file or its constructor.
    volume = isotile.read_volume(ball)
    with pytest.raises(ValueError, match="^spacing, series apply only to a path or an array"):
        isotile.extract(volume, 100, spacing=(2, 2, 2), series="1.2")
    with pytest.raises(ValueError,
                       match=r"^spacing must be three numbers \(x, y, z\), not \(1.0, 1.0\)"):
        isotile.Volume(array, spacing=(1, 1))
    with pytest.raises(ValueError, match="^direction must be 3x3"):
        isotile.Volume(array, direction=np.eye(2))
    with pytest.raises(ValueError, match="^spacing applies only to a path or an array"):
        isotile.extract(isotile.Volume(array), 0.5, spacing=(3, 3, 3))
    volume.spacing = (2.0, 2.0, 2.0)
    with pytest.raises(ValueError, match="changed after read_volume"):
        isotile.extract(volume, 100)
    # Values of the wrong kind: a ValueError naming the keyword, not pybind11's TypeError that
    # prints the arguments (the whole volume).
    for bad in (1.5, "2", True, 0):
        with pytest.raises(ValueError, match="^threads must be an int from 1 to 4096"):
            isotile.extract(array, 0.5, threads=bad)
        with pytest.raises(ValueError, match="^threads must be an int from 1 to 4096"):
            isotile.marching_cubes(array, 0.5, threads=bad)
    assert isotile.extract(array, 0.5, threads=np.int64(1), stats=False).faces.shape[0] > 0
    with pytest.raises(ValueError, match="^memory must be a byte count"):
        isotile.extract(ball, 100, memory=True, output=tmp_path / "m.ply")
    with pytest.raises(ValueError, match="^ascii applies to the output file"):
        isotile.extract(ball, 100, ascii=True)
    # marching_cubes refuses Macet's quality with another method, as extract does.
    with pytest.raises(ValueError, match="^quality applies to method=\"macet\" only"):
        isotile.marching_cubes(array, 0.5, method="lorensen", quality="max")


def test_simplify_names_a_bad_target():
    mesh = isotile.extract("field:sphere:16", stats=False)
    v, f = mesh.vertices, mesh.faces
    with pytest.raises(ValueError, match="^ratio must be in \\(0, 1\\], not 0$"):
        isotile.simplify(v, f, ratio=0)
    with pytest.raises(ValueError, match="^faces must be an int of at least 1, not -1$"):
        isotile.simplify(v, f, faces=-1)
    with pytest.raises(ValueError, match="^faces must be an int of at least 1, not 0$"):
        isotile.simplify(v, f, faces=0)
    with pytest.raises(ValueError, match="^max_error must be above 0, not 0$"):
        isotile.simplify(v, f, max_error=0)
    assert len(isotile.simplify(v, f, faces=np.int64(100))[1]) <= 100
    # A target the checks do not let it reach, by more than a tenth: a RuntimeWarning.
    g = isotile.extract("field:gyroid:64", stats=False)
    with pytest.warns(RuntimeWarning, match="^simplification stopped at .* above its target of 3850") as said:
        isotile.simplify(g.vertices, g.faces, ratio=0.05)
    assert said[0].filename == __file__
    # Not where the error bound, the other target, stopped it first.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        isotile.simplify(g.vertices, g.faces, ratio=0.05, max_error=0.01)
    # Two face counts at once: refused (faces won and ratio was dropped without a word).
    with pytest.raises(ValueError, match="^give ratio or faces, not both"):
        isotile.simplify(v, f, ratio=0.2, faces=10)
    with pytest.raises(ValueError, match="^faces must be below 2\\*\\*64, not 18446744073709551716$"):
        isotile.simplify(v, f, faces=2**64 + 100)


def test_the_runs_warnings_are_python_warnings(tmp_path, capfd):
    """A warning of the run (a budget that Macet's one-cell slices of torus 33 overflow) is a
    RuntimeWarning at the caller's line, not a line on stderr; the file is still exact. Made an
    error by a warnings filter, it stops the run and leaves no file."""
    torus = dict(method="macet", stats=False)
    isotile.extract("field:torus:33", output=tmp_path / "in.ply", **torus)
    with pytest.warns(RuntimeWarning, match="memory budget of 12000 bytes is too small") as said:
        isotile.extract("field:torus:33", memory=12000, output=tmp_path / "ooc.ply", **torus)
    # The tiler's tables of counts first: at this budget they alone exceed it.
    assert len(said) == 2
    assert "leaves out the tiler's tables of counts" in str(said[0].message)
    assert all(w.filename == __file__ for w in said)
    assert (tmp_path / "ooc.ply").read_bytes() == (tmp_path / "in.ply").read_bytes()
    assert "warning" not in capfd.readouterr().err
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(RuntimeWarning, match="memory budget of 12000 bytes"):
            isotile.extract("field:torus:33", memory=12000, output=tmp_path / "err.ply", **torus)
    assert not (tmp_path / "err.ply").exists()


def test_an_arrays_samples_pass_a_files_checks():
    """An array handed to extract is checked as a file's samples are: NaN or Inf, and no samples
    at all, are errors, not a mesh with NaN vertices or a range made up."""
    vol = np.zeros((16, 16, 16), np.float32)
    vol[4:12, 4:12, 4:12] = 1
    vol[8, 8, 3] = np.nan
    with pytest.raises(ValueError, match="1 sample is NaN or Inf .first at x=3, y=8, z=8"):
        isotile.extract(vol, 0.5)
    with pytest.raises(ValueError, match="NaN or Inf"):
        isotile.extract(isotile.Volume(vol), 0.5)
    with pytest.raises(ValueError, match="volume dimensions must be positive"):
        isotile.extract(np.zeros((0, 4, 4), np.float32), 0.0, allow_empty=True)


def test_a_volume_one_sample_thick_has_no_surface():
    """No cells, so no face: an error as for any run without a face (allow_empty: the empty
    mesh), not an empty mesh without a word."""
    flat = np.linspace(0, 1, 256, dtype=np.float32).reshape(1, 16, 16)
    with pytest.raises(ValueError, match="no face crosses it"):
        isotile.extract(flat, 0.5)
    assert len(isotile.extract(flat, 0.5, allow_empty=True).faces) == 0


def test_a_warning_made_an_error_keeps_the_previous_file(tmp_path):
    """A warning turned into an error by a filter cancels the run before it writes: the file
    from before stays as it was, however quickly the run ends (the run waits for the warning to
    be issued)."""
    vol = np.zeros((8, 8, 8), np.float32)
    vol[2:6, 2:6, 2:6] = 1
    out = tmp_path / "keep.ply"
    for _ in range(5):
        out.write_text("my previous mesh")
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            with pytest.raises(RuntimeWarning, match="positions are float32"):
                isotile.extract(vol, 0.5, origin=(1e7, 0, 0), output=out)
        assert out.read_text() == "my previous mesh"


def test_coarse_float32_positions_are_a_warning(tmp_path):
    """A grid so far from 0 that float32 vertices snap to a coarse lattice (UTM-like) is said as
    a RuntimeWarning; the mesh still comes back. A grid nearer 0 is not."""
    vol = np.zeros((12, 12, 12), np.float32)
    vol[3:9, 3:9, 3:9] = 1
    with pytest.warns(RuntimeWarning, match="positions are float32: .* about 2 steps per cell"):
        mesh = isotile.extract(vol, 0.5, origin=(5e6, 5e6, 0), stats=False)
    assert len(mesh.faces) > 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        isotile.extract(vol, 0.5, origin=(5e5, 5e5, 0), stats=False)


# --- progress, cancel, Ctrl-C: a tiled run of many bricks (the loops that report today) --------

MANY_BRICKS = dict(memory="256KiB")


def test_progress_reports_every_brick_of_both_passes(tmp_path):
    calls = []
    stats = isotile.extract("field:gyroid:96", output=tmp_path / "m.ply",
                            progress=lambda *a: calls.append(a) or True, **MANY_BRICKS)
    bricks = stats["bricks"]
    assert bricks >= 20
    for stage in ("count", "extract"):
        done = {b for s, b, n, f in calls if s == stage and f == 1.0}
        assert done == set(range(bricks)), stage
        assert all(n == bricks for s, b, n, f in calls if s == stage)
    assert all(0.0 <= f <= 1.0 for *_, f in calls)


def left_in(folder):
    return sorted(p.name for p in pathlib.Path(folder).iterdir())


def test_a_false_return_cancels_and_leaves_no_file(tmp_path):
    seen = []

    def stop_after_ten(stage, brick, bricks, fraction):
        seen.append(stage)
        return len(seen) < 10

    with pytest.raises(isotile.Cancelled):
        isotile.extract("field:gyroid:96", output=tmp_path / "m.ply", progress=stop_after_ten,
                        **MANY_BRICKS)
    assert len(seen) == 10  # not called again once it said stop
    assert left_in(tmp_path) == []


def test_a_callback_that_returns_nothing_goes_on(tmp_path):
    """None is no answer: a callback that only prints (or logs) watches the run, it does not
    cancel it at its first call."""
    calls = []
    stats = isotile.extract("field:gyroid:96", output=tmp_path / "m.ply",
                            progress=lambda *a: calls.append(a), **MANY_BRICKS)
    assert len(calls) >= 2 * stats["bricks"]
    assert (tmp_path / "m.ply").exists()


def test_the_callbacks_exception_cancels_and_propagates(tmp_path):
    class Stop(Exception):
        pass

    def fail(stage, brick, bricks, fraction):
        if stage == "extract" and brick == 3:
            raise Stop("enough")
        return True

    with pytest.raises(Stop, match="enough"):
        isotile.extract("field:gyroid:96", output=tmp_path / "m.ply", progress=fail,
                        **MANY_BRICKS)
    assert left_in(tmp_path) == []


def test_ctrl_c_raises_keyboard_interrupt_within_half_a_second_and_leaves_no_file(tmp_path):
    sent = []

    def interrupt(stage, brick, bricks, fraction):
        if stage == "count" and brick == 5 and not sent:
            sent.append(time.monotonic())
            os.kill(os.getpid(), signal.SIGINT)
        return True

    with pytest.raises(KeyboardInterrupt):
        isotile.extract("field:gyroid:128", output=tmp_path / "m.ply", progress=interrupt,
                        **MANY_BRICKS)
    assert sent
    assert time.monotonic() - sent[0] < 0.5
    assert left_in(tmp_path) == []
    # Without a progress callable too: the signal is watched all the same.
    import threading
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT))
    start = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            # Enough bricks to outlast the timer many times over.
            isotile.extract("field:gyroid:256", output=tmp_path / "n.ply", stats=False,
                            **MANY_BRICKS)
    finally:
        timer.cancel()
    assert time.monotonic() - start < 0.05 + 0.5
    assert left_in(tmp_path) == []


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_the_process_and_leave_no_temporary(tmp_path, sig):
    # Nothing in Python handles them: the process ends at once, and the run's temporary (out of
    # core, the mesh's size) was left behind.
    script = (
        "import sys, isotile\n"
        "def started(stage, brick, bricks, fraction):\n"
        "    if stage == 'extract' and brick == 2:\n"
        "        print('started', flush=True)\n"
        "    return True\n"
        "isotile.extract('field:gyroid:256', output='m.ply', memory='256KiB', stats=False,\n"
        "                progress=started)\n")
    child = subprocess.Popen([sys.executable, "-c", script], cwd=tmp_path, stdout=subprocess.PIPE,
                             text=True)
    try:
        assert child.stdout.readline() == "started\n"
        child.send_signal(sig)
        assert child.wait(timeout=60) == -sig
    finally:
        child.kill()
        child.wait()
    assert left_in(tmp_path) == []


def test_a_volume_that_cannot_fit_is_refused_with_a_budget_that_runs(tmp_path):
    # In a child whose address space leaves 300 MiB: the 512 MiB of a 512^3 field cannot be read
    # in core. The refusal names the keywords, and the budget it gives runs within the same limit
    # and writes the in-core run's file.
    script = (
        "import re, resource, isotile\n"
        "with open('/proc/self/status') as f:\n"
        "    vm = next(int(l.split()[1]) for l in f if l.startswith('VmSize:')) * 1024\n"
        "resource.setrlimit(resource.RLIMIT_AS, (vm + (300 << 20), resource.RLIM_INFINITY))\n"
        "try:\n"
        "    isotile.extract('field:gyroid:512', iso=0)\n"
        "except MemoryError as e:\n"
        "    print(e)\n"
        "    budget = re.search(r'within SIZE \\(e\\.g\\. (\\w+)\\)', str(e)).group(1)\n"
        "    isotile.extract('field:gyroid:512', iso=0, memory=budget, output='streamed.ply',\n"
        "                    stats=False)\n")
    r = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "in core, its samples alone take 512 MiB" in r.stdout, r.stdout
    assert 'give memory="SIZE" and output="FILE" to extract it brick by brick' in r.stdout
    isotile.write_mesh(tmp_path / "in_core.ply", isotile.extract("field:gyroid:512", iso=0))
    assert (tmp_path / "streamed.ply").read_bytes() == (tmp_path / "in_core.ply").read_bytes()


# --- mesh files ------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["m.ply", "m.obj", "m.stl", "m.off"])
def test_read_mesh_and_write_mesh_round_trip_the_clis_files(tmp_path, name):
    r = run_cli_in(tmp_path, "field:gyroid:24", "--method", "dc", "--normals", "-o", name)
    assert r.returncode == 0, r.stderr
    mesh = isotile.read_mesh(tmp_path / name)
    assert len(mesh.faces) > 100 and mesh.vertices.dtype == np.float32
    isotile.write_mesh(tmp_path / ("again_" + name), mesh)
    assert (tmp_path / ("again_" + name)).read_bytes() == (tmp_path / name).read_bytes()
    isotile.write_mesh(tmp_path / "pair.ply", (mesh.vertices, mesh.faces))
    assert np.array_equal(isotile.read_mesh(tmp_path / "pair.ply").faces, mesh.faces)
    with pytest.raises(ValueError, match="past the"):
        isotile.write_mesh(tmp_path / "bad.ply", (mesh.vertices, mesh.faces + len(mesh.vertices)))
    assert not (tmp_path / "bad.ply").exists()


# --- reader modules: loaded from the extension's folder in a Python process ------------------

def write_mha(path, samples, spacing=(1.0, 1.0, 1.0)):
    z, y, x = samples.shape
    header = ("ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
              f"DimSize = {x} {y} {z}\nElementSpacing = {spacing[0]} {spacing[1]} {spacing[2]}\n"
              "Offset = 0 0 0\nElementType = MET_FLOAT\nElementDataFile = LOCAL\n")
    path.write_bytes(header.encode() + samples.astype("<f4").tobytes())


def loaded_objects():
    return pathlib.Path("/proc/self/maps").read_text()


def test_a_module_backed_format_loads_its_reader_module_into_python(tmp_path, monkeypatch):
    package = pathlib.Path(isotile.__file__).parent
    if not (package / "libisotile_itk_reader.so").exists():
        skip("itk", "this build has no ITK reader module (ISOTILE_ITK=OFF)")
    z, y, x = np.indices((20, 22, 24))
    samples = 9.0 - np.sqrt((x - 11.5) ** 2 + (y - 10.5) ** 2 + (z - 9.5) ** 2)
    write_mha(tmp_path / "ball.mha", samples)
    volume = isotile.read_volume(tmp_path / "ball.mha")
    # Found beside the extension (tiler/reader_modules.cpp), not through the isotile program.
    assert os.path.realpath(package / "libisotile_itk_reader.so") in loaded_objects()
    assert np.array_equal(volume.samples, samples.astype(np.float32))
    r = run_cli_in(tmp_path / "cli", tmp_path / "ball.mha", "--iso", "0", "-o", "m.ply",
                   "--stats", "s.json")
    assert r.returncode == 0, r.stderr
    monkeypatch.chdir(tmp_path)
    mesh = isotile.extract(tmp_path / "ball.mha", 0, output="cli/py.ply")
    assert (tmp_path / "cli" / "py.ply").read_bytes() == (tmp_path / "cli" / "m.ply").read_bytes()
    want = steady(json.loads((tmp_path / "cli" / "s.json").read_text()))
    got = steady(mesh.stats)
    assert got.pop("output") == "cli/py.ply" and want.pop("output") == "m.ply"
    assert got == want
