# Shared helpers of the Python tests (run by ctest: tests/CMakeLists.txt sets PYTHONPATH to the
# build tree's package, ISOTILE_CLI and ISOTILE_SHARED_DATA).
#
# Skips follow the C++ suites' rule (tests/skip_support.h): a test that cannot run says why and
# of which kind; where ISOTILE_STRICT_SKIPS names that kind (or "all"), the skip is a failure.
import gzip
import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SHARED_DATA = pathlib.Path(os.environ.get("ISOTILE_SHARED_DATA", REPO.parent / "shared" / "data"))


def skip(kind, message):
    strict = os.environ.get("ISOTILE_STRICT_SKIPS", "").split(",")
    if "all" in strict or kind in strict:
        pytest.fail(f"cannot run ({kind} is required by ISOTILE_STRICT_SKIPS): {message}")
    pytest.skip(message)


def require(module):
    """The Debian Python module `module` (skimage, meshio, vtk), or a skip of kind python."""
    try:
        return __import__(module)
    except ImportError as e:
        skip("python", f"{module} is not importable ({e}); setup.sh installs it")


def cli():
    path = os.environ.get("ISOTILE_CLI")
    if not path or not os.path.exists(path):
        pytest.fail("ISOTILE_CLI does not name the built isotile program (run through ctest)")
    return path


def run_cli(*args):
    r = subprocess.run([cli(), *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r.stdout


def bonsai():
    """bonsai as a C-ordered uint8 [z, y, x] array, or a skip of kind shared-data."""
    path = SHARED_DATA / "bonsai_256x256x256_uint8.raw.gz"
    if not path.exists():
        skip("shared-data", f"no shared data at {path}")
    with gzip.open(path, "rb") as f:
        return np.frombuffer(f.read(), dtype=np.uint8).reshape(256, 256, 256)


def sphere(shape=(40, 48, 56), center=None, radius=15.0, dtype=np.float32):
    """Distance-like field, bright inside: radius - |p - center| (voxels), [z, y, x]."""
    z, y, x = np.indices(shape, dtype=np.float64)
    c = np.array(center if center is not None else [(s - 1) / 2 for s in shape])
    d = np.sqrt((z - c[0]) ** 2 + (y - c[1]) ** 2 + (x - c[2]) ** 2)
    return (radius - d).astype(dtype)


def read_ply(path):
    """Positions (x, y, z float32), normals or None, and faces (int64) of a binary little-endian
    PLY as the isotile program writes it."""
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    assert "format binary_little_endian 1.0" in header, header
    elements, current = [], None
    for line in header:
        w = line.split()
        if w[0] == "element":
            current = [w[1], int(w[2]), []]
            elements.append(current)
        elif w[0] == "property":
            current[2].append(w[1:])
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "uint8": "u1", "int": "<i4",
             "int32": "<i4", "uint": "<u4", "uint32": "<u4", "char": "i1", "short": "<i2",
             "ushort": "<u2"}
    pos, out = end, {}
    for name, count, props in elements:
        if props[0][0] == "list":
            count_t, index_t = np.dtype(types[props[0][1]]), np.dtype(types[props[0][2]])
            # isotile writes triangles only: every row is (3, a, b, c).
            row = np.dtype([("n", count_t), ("i", index_t, 3)])
            a = np.frombuffer(data, dtype=row, count=count, offset=pos)
            assert (a["n"] == 3).all()
            out[name] = a["i"].astype(np.int64)
            pos += row.itemsize * count
        else:
            row = np.dtype([(p[1], types[p[0]]) for p in props])
            a = np.frombuffer(data, dtype=row, count=count, offset=pos)
            out[name] = a
            pos += row.itemsize * count
    v = out["vertex"]
    positions = np.stack([v["x"], v["y"], v["z"]], axis=1)
    normals = (np.stack([v["nx"], v["ny"], v["nz"]], axis=1)
               if "nx" in v.dtype.names else None)
    return positions, normals, out.get("face", np.zeros((0, 3), np.int64))


def signed_volume(verts, faces):
    v = np.asarray(verts, dtype=np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def two_way_distance(a, b):
    """Largest distance from a vertex of one set to the nearest vertex of the other."""
    from scipy.spatial import cKDTree
    return max(cKDTree(b).query(a)[0].max(), cKDTree(a).query(b)[0].max())
