"""isotile: isosurface meshes from NumPy volumes, on isotile's C++ libraries.

``isotile.marching_cubes`` is a drop-in for ``skimage.measure.marching_cubes`` (scikit-image
0.19): same arguments (and more), same return tuple, same conventions, many times faster, with
Macet and Dual Contouring besides Marching Cubes. ``isotile.quality`` measures a mesh and
``isotile.simplify`` simplifies one. See docs/python.md.

``isotile.extract`` is ``isotile extract`` for Python: the library's one pipeline (the program's,
the MeshLab plugin's) on a file, a DICOM directory, a procedural field, a ``Volume`` from
``isotile.read_volume`` or an array; in core it returns a ``Mesh``, out of core (``memory=``) it
streams the mesh into ``output=``. Its statistics are ``--stats``'s. ``read_mesh`` and
``write_mesh`` read and write the formats the library writes (PLY, OBJ, STL, OFF).

Volumes are read in place, without a copy, for int8, uint8, int16, uint16, int32, uint32,
float32, float64 and bool arrays in any memory layout whose strides are non-negative multiples
of the item size (C or Fortran order, slices such as ``vol[::2, :, 10:]``). Anything else is
copied first: float16 to float32, int64 and uint64 to float64 (exact up to 2**53), reversed
axes (negative strides), unaligned or byte-swapped data to a C-ordered array. The arrays returned
own the library's buffers (no copy).
"""

import json as _json
import numbers as _numbers
import operator as _operator
import os as _os

import numpy as _np

from . import _isotile

__all__ = ["marching_cubes", "quality", "simplify", "backends", "extract", "read_volume",
           "Volume", "Mesh", "read_mesh", "write_mesh", "Cancelled", "NoSurface"]

__version__ = _isotile.__version__  # the C++ library's, as `isotile --version` prints it
Cancelled = _isotile.Cancelled
# No face at the isovalue: both a ValueError (extract's bad inputs) and a RuntimeError (what
# scikit-image's marching_cubes raises).
NoSurface = _isotile.NoSurface

_IN_PLACE = {_np.dtype(t) for t in ("int8", "uint8", "int16", "uint16", "int32", "uint32",
                                   "float32", "float64", "bool")}
_METHODS = {"lewiner": "mc", "lorensen": "mc", "mc": "mc", "macet": "macet", "dc": "dc"}


def _readable(array, what):
    """`array` as the library reads it: itself when it can, else the documented copy."""
    a = _np.asarray(array)
    if a.dtype.kind not in "biuf":
        raise TypeError(f"{what}: dtype {a.dtype} is not a number type")
    # The library reads a bool's byte; NumPy's True is any byte but 0 (a uint8 array viewed as
    # bool holds 2s and 255s), so such an array is read as the 0s and 1s it means.
    if a.dtype.kind == "b" and a.size:
        u = a.view(_np.uint8)
        # Plane by plane: a reduction over a strided whole buffers as much as a copy.
        if max(int(p.max()) for p in (u if u.ndim > 1 else [u])) > 1:
            a = u != 0
    dtype = a.dtype.newbyteorder("=")
    if dtype not in _IN_PLACE:
        dtype = _np.dtype(_np.float32 if a.dtype.kind == "f" and a.dtype.itemsize < 4
                          else _np.float64)
    in_place = (dtype == a.dtype and a.flags.aligned
                and all(s >= 0 and s % a.itemsize == 0 for s in a.strides))
    # A copy, always: ascontiguousarray returns an unaligned C-ordered array as it is.
    return a if in_place else _np.array(a, dtype=dtype, order="C", copy=True)


def marching_cubes(volume, level=None, *, spacing=(1., 1., 1.), gradient_direction="descent",
                   step_size=1, allow_degenerate=True, method="lewiner", mask=None,
                   quality="fast", backend="cpu", threads=None, normals=True):
    """Isosurface of a 3-D array; scikit-image's ``measure.marching_cubes``, on isotile.

    Parameters
    ----------
    volume : (M, N, P) array
        Samples indexed [axis 0, axis 1, axis 2] (e.g. [z, y, x]). Read in place for 8-, 16- and
        32-bit integers, float32, float64 and bool in any layout with non-negative strides;
        float16, int64 and uint64 are copied to float32 / float64 first.
    level : float, optional
        Isovalue. None: the middle of the data's range, (min + max) / 2. A level outside the
        range, or NaN, raises ValueError. Samples equal to the level count as inside (scikit-image
        counts them as outside): on integer data a level between sample values (0.5, not 1)
        gives the same surface in both.
    spacing : 3 floats
        Distance between samples along axis 0, 1, 2.
    gradient_direction : "descent" or "ascent"
        "descent" (the default): the object is brighter than its surroundings, and faces are
        wound as scikit-image winds them for it; "ascent" reverses the winding.
    step_size : int
        Use every step_size-th sample along each axis (a strided view, no copy).
    allow_degenerate : bool
        False removes what scikit-image removes: triangles with two corners at one point
        (vertices at one position are merged first, unused ones dropped). They arise where
        samples equal the level; an isovalue between sample values avoids them.
    method : "lewiner", "lorensen", "mc", "macet" or "dc"
        "lewiner" and "lorensen" run isotile's Marching Cubes (VTK's case table, so triangle
        counts may differ slightly from scikit-image's), "macet" Macet, "dc" Dual Contouring.
    mask : (M, N, P) bool array, optional
        Faces are kept only in cells whose eight corner samples are all True (the cell holding
        the face's centroid); scikit-image looks at one corner of each cell instead.
    quality : "fast" or "max"
        Macet's quality mode.
    backend : "cpu", "gs", "hp" or "auto"
        Where to extract: the CPU, or OpenGL (geometry shaders, HistoPyramids).
    threads : int, optional
        At most this many threads while the call runs (None: all cores): a limit on the
        process's thread pool, which other isotile calls running meanwhile share. The result
        does not depend on it.
    normals : bool
        Compute per-vertex normals (True, as scikit-image does); False returns None for them.

    Returns
    -------
    verts : (V, 3) float32 array
        Vertex positions in the array's axis order, scaled by spacing.
    faces : (F, 3) int32 array
        Triangles, indices into verts.
    normals : (V, 3) float32 array or None
        Unit normals from the data's gradient, pointing down it (out of the bright object), in
        the array's axis order; (0, 0, 0) where the gradient vanishes.
    values : (V,) float32 array
        As scikit-image defines them: for each vertex, the largest (max - min) of the samples of
        the cells it lies in.

    Raises
    ------
    ValueError
        Not a 3-D array, smaller than 2x2x2, level outside the data's range or not finite, NaN
        samples, a bad argument; or the library's message for invalid input.
    TypeError
        A dtype that is not a number.
    RuntimeError
        No surface at the given level.

    Warns
    -----
    RuntimeWarning
        With backend="auto", a GPU backend that failed (the CPU's mesh is returned).
    """
    if not isinstance(volume, _np.ndarray) or volume.ndim != 3:
        raise ValueError("Input volume should be a 3D numpy array.")
    if volume.shape[0] < 2 or volume.shape[1] < 2 or volume.shape[2] < 2:
        raise ValueError("Input array must be at least 2x2x2.")
    if method not in _METHODS:
        raise ValueError("method should be one of 'lewiner', 'lorensen', 'mc', 'macet' or 'dc'.")
    if gradient_direction not in ("descent", "ascent"):
        raise ValueError(f"Incorrect input {gradient_direction} in `gradient_direction`, see "
                         "docstring.")
    try:
        spacing = tuple(float(s) for s in spacing) if not isinstance(spacing, str) else ()
    except (TypeError, ValueError):
        spacing = ()
    if len(spacing) != 3:
        raise ValueError("`spacing` must consist of three floats.")
    # scikit-image takes any spacing; zero flattens the mesh, a negative one turns it inside
    # out and a non-finite one gives non-finite vertices, so isotile refuses them, as its files do.
    if not all(_np.isfinite(s) and s > 0 for s in spacing):
        raise ValueError(f"`spacing` must be finite and positive, got {spacing}.")
    step_size = int(step_size)
    if step_size < 1:
        raise ValueError("step_size must be at least one.")
    # Every step_size-th sample: fewer than 2 along an axis leaves no cell. scikit-image says "no
    # surface" (RuntimeError, kept for code that catches it); this says why.
    if any((n - 1) // step_size + 1 < 2 for n in volume.shape):
        raise NoSurface(f"No surface found: step_size {step_size} leaves fewer than 2 samples "
                        f"along an axis of the {volume.shape} array.")
    if mask is not None:
        mask = _np.asarray(mask)
        if mask.shape != volume.shape:
            raise ValueError("volume and mask must have the same shape.")
        if mask.dtype != _np.bool_:
            mask = mask.astype(_np.bool_)
    _check_threads(threads)
    whole = _readable(volume, "volume")
    vol = whole
    if step_size > 1:
        vol = whole[::step_size, ::step_size, ::step_size]
        if mask is not None:
            mask = mask[::step_size, ::step_size, ::step_size]
    if mask is not None:
        mask = _readable(mask, "mask")
    spacing_xyz = tuple(float(s) * step_size for s in reversed(tuple(spacing)))
    # The library checks the level against the whole volume's range (None: its middle), as
    # scikit-image does whatever the step, then extracts from the strided view.
    verts, faces, norms, values = _isotile.extract(
        vol, whole, None if level is None else float(level), spacing_xyz, _METHODS[method],
        quality, backend, bool(normals), True, mask, threads)
    if len(faces) == 0:
        raise NoSurface("No surface found at the given iso value." + (
            " Dual Contouring makes no face where the surface meets only the array's border "
            "(a 2x2x2 array has no edge inside)." if method == "dc" else ""))
    if not allow_degenerate:
        verts, faces, norms, values = _without_repeated_points(verts, faces, norms, values)
        # Every triangle had two corners at one point (the level is a sample value at which the
        # surface has no area): no surface, as the docstring says, not empty arrays.
        if len(faces) == 0:
            raise NoSurface("No surface found at the given iso value: every triangle has two "
                            "corners at one point (samples equal to the level count as inside).")
    # Views, no copies: columns reversed into the array's axis order (a mirror, which turns the
    # library's winding into scikit-image's for "descent"); "ascent" reverses the winding.
    verts = verts[:, ::-1]
    if norms is not None:
        norms = norms[:, ::-1]
    if gradient_direction == "ascent":
        faces = faces[:, ::-1]
    return verts, faces, norms, values


def _without_repeated_points(verts, faces, norms, values):
    """What scikit-image's allow_degenerate=False removes: vertices at one position become the
    first of them, the triangles that then repeat a vertex go (their area is zero), and so do
    the vertices no triangle uses. Zero-area triangles with three distinct corners stay, as
    there."""
    _, first, inverse = _np.unique(verts, axis=0, return_index=True, return_inverse=True)
    f = first[inverse.reshape(-1)][faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    used = _np.zeros(len(verts), bool)
    used[f.reshape(-1)] = True
    renumber = _np.cumsum(used) - 1
    return (verts[used], renumber[f].astype(faces.dtype), None if norms is None else norms[used],
            values[used])


def quality(vertices, faces, *, check_intersections=False, threads=None):
    """The measures ``isotile quality --json`` reports for a triangle mesh, as a dict.

    Radius ratio (2 r_in / R_circ: 1 equilateral, 0 degenerate) min, mean, median, 0.1% and 1%
    quantiles and histogram; degenerate triangles; boundary, non-manifold and inconsistently
    oriented edges; non-manifold vertices; Euler characteristic; components; closed; and with
    check_intersections, the number of self-intersecting triangle pairs. ``watertight`` and
    ``border_boundary_edges`` are None: arrays carry no volume box to tell border edges from
    holes. The arrays are copied into the library's mesh.
    """
    _check_threads(threads)
    return _isotile.quality(_np.asarray(vertices), _np.asarray(faces), bool(check_intersections),
                            threads)


def simplify(vertices, triangles, /, *, ratio=None, faces=None, max_error=None, min_quality=0.3,
             relax=True, threads=None):
    """Simplify a triangle mesh by edge collapses that keep its shape, topology and border.

    ``simplify(verts, faces, ratio=0.1)``, ``faces=N`` or ``max_error=E``, as ``isotile simplify``
    takes ``--ratio``, ``--faces`` and ``--max-error``. Stops at the first target reached: ``faces``
    faces (or ``ratio`` of the input's faces; one of the two, not both)
    and, with ``max_error``, the error bound in mesh units. At least one must be given. Returns
    (vertices, faces) as new arrays; the result does not depend on ``threads``.
    """
    if ratio is None and faces is None and max_error is None:
        raise ValueError("simplify needs ratio, faces or max_error")
    if ratio is not None and faces is not None:
        # Two face counts: the library takes faces and drops ratio, which would go unsaid.
        raise ValueError("give ratio or faces, not both: both say how many faces to keep")
    _check_threads(threads)
    # 0 stands for "not given" below: an explicit 0 (or less) is refused here, naming it.
    if ratio is not None and not 0 < ratio <= 1:
        raise ValueError(f"ratio must be in (0, 1], not {ratio!r}")
    if faces is not None and (isinstance(faces, bool) or not isinstance(faces, _numbers.Integral)
                              or faces < 1):
        raise ValueError(f"faces must be an int of at least 1, not {faces!r}")
    if faces is not None and faces >= 2**64:
        raise ValueError(f"faces must be below 2**64, not {faces!r}")
    if max_error is not None and not max_error > 0:
        raise ValueError(f"max_error must be above 0, not {max_error!r}")
    return _isotile.simplify(_np.asarray(vertices), _np.asarray(triangles),
                             0.0 if ratio is None else float(ratio),
                             0 if faces is None else int(faces),
                             0.0 if max_error is None else float(max_error), float(min_quality),
                             bool(relax), threads)


def backends():
    """{backend name: "" when this machine can run it, else why it cannot}."""
    return _isotile.backends()


# --- files, volumes and the pipeline -------------------------------------------------------------

def _triple_text(value):
    """(x, y, z) as the CLI's text "x,y,z" (repr: exact for floats); text passes through."""
    if value is None or isinstance(value, str):
        return value
    # repr of the plain float: NumPy 2's repr of its float64 (a float) is "np.float64(0.5)".
    return ",".join(repr(float(v)) if isinstance(v, float) else str(v) for v in value)


def _same_matrix(a, b):
    """Whether two 3x3 matrices (lists or arrays; None for none) hold the same numbers."""
    if a is None or b is None:
        return a is None and b is None
    return _np.array_equal(_np.asarray(a, dtype=float), _np.asarray(b, dtype=float))


def _dims_text(dims):
    """dims as the CLI's text; sample counts are integers (28.0 was refused as not "three
    comma-separated numbers", which it is)."""
    if dims is None or isinstance(dims, str):
        return dims
    try:
        return ",".join(str(_operator.index(n)) for n in dims)
    except TypeError:
        raise ValueError(f"dims must be three integers (samples along x, y, z), got {dims!r}") \
            from None


def _raw_options(dims, type, spacing, origin, endian, series):
    return {"dims": _dims_text(dims), "type": type, "spacing": _triple_text(spacing),
            "origin": _triple_text(origin), "endian": endian, "series": series}


class Volume:
    """Samples on a uniform grid: ``samples`` indexed [z, y, x] (x fastest, as files store them),
    ``spacing`` and ``origin`` (x, y, z) and ``direction`` (3x3, column a the world direction of
    index axis a; None for an array's Volume: the identity, a plain grid).

    ``isotile.read_volume`` makes one from a file, with the samples in the library's buffer
    (read-only, no copy); ``Volume(samples, spacing, origin, direction)`` wraps an array.
    """

    def __init__(self, samples, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), direction=None):
        self._handle = self._read_samples = None
        self.samples = _np.asarray(samples)
        if self.samples.ndim != 3:
            raise ValueError("samples must be a 3-D array indexed [z, y, x]")
        self.spacing = tuple(float(v) for v in spacing)
        self.origin = tuple(float(v) for v in origin)
        self.direction = None if direction is None else [[float(v) for v in row]
                                                         for row in direction]
        # Checked here, not at the first extract: the mistake is made here.
        for name in ("spacing", "origin"):
            if len(getattr(self, name)) != 3:
                raise ValueError(f"{name} must be three numbers (x, y, z), not "
                                 f"{getattr(self, name)!r}")
        if self.direction is not None and (len(self.direction) != 3
                                           or any(len(row) != 3 for row in self.direction)):
            raise ValueError("direction must be 3x3")
        self.name = "array"

    @classmethod
    def _from_handle(cls, handle):
        v = cls.__new__(cls)
        v._handle = handle
        v.samples = v._read_samples = handle.samples
        v.spacing = tuple(handle.spacing)
        v.origin = tuple(handle.world_origin)
        v.direction = [list(row) for row in handle.direction]
        v.name = handle.name
        return v

    def __repr__(self):
        z, y, x = self.samples.shape
        return f"Volume({self.name!r}, {x}x{y}x{z} {self.samples.dtype}, spacing={self.spacing})"


def read_volume(path, *, dims=None, type=None, spacing=None, origin=None, endian="little",
                series=None):
    """Read any input ``isotile extract`` reads: a volume file (NRRD, NIfTI, MetaImage, TIFF,
    MRC, DICOM, OpenVDB, raw), a DICOM or TIFF directory, a numbered TIFF pattern or a
    procedural field ``field:NAME:N``. ``dims``, ``type``, ``spacing``, ``origin``, ``endian`` and
    ``series`` are the CLI's ``--dims`` ... ``--series`` (a tuple or the CLI's text). Returns a
    ``Volume``; ``extract(volume)`` gives the same mesh as ``extract(path)``."""
    handle = _isotile.read_volume(_os.fspath(path),
                                  _raw_options(dims, type, spacing, origin, endian, series))
    return Volume._from_handle(handle)


class Mesh:
    """A mesh as the library makes it: ``vertices`` (V, 3) float32 (x, y, z), ``faces`` (F, 3)
    triangles, ``quads`` (Q, 4) (Dual Contouring with ``quads=True``; else empty), ``normals``
    (V, 3) float32 or None, and ``stats``: the dict ``isotile extract --stats`` writes (None when
    not asked for). ``save(path)`` writes it as ``isotile extract -o path`` does."""

    def __init__(self, vertices, faces, quads=None, normals=None, stats=None):
        self.vertices = vertices
        self.faces = faces
        self.quads = quads if quads is not None else _np.zeros((0, 4), _np.int32)
        self.normals = normals
        self.stats = stats

    def save(self, path, *, ascii=False):
        """Write the mesh: .ply (binary, or ASCII with ascii=True), .obj, .stl or .off, by
        extension (normals in PLY and OBJ). The file is replaced whole or not at all."""
        write_mesh(path, self, ascii=ascii)

    def __repr__(self):
        return (f"Mesh({len(self.vertices)} vertices, {len(self.faces)} triangles, "
                f"{len(self.quads)} quads)")


def read_mesh(path):
    """Read a .ply, .obj, .stl or .off file into a ``Mesh`` (stats None)."""
    vertices, faces, quads, normals = _isotile.read_mesh(_os.fspath(path))
    return Mesh(vertices, faces, quads, normals)


def write_mesh(path, mesh, *, ascii=False):
    """Write ``mesh`` (a ``Mesh``, or a (vertices, faces) pair) to ``path`` as the library writes
    meshes: .ply (binary; ascii=True for text), .obj, .stl or .off by extension."""
    if isinstance(mesh, Mesh):
        v, f, q, n = mesh.vertices, mesh.faces, mesh.quads, mesh.normals
    else:
        v, f = mesh
        q = n = None
    _isotile.write_mesh(_np.asarray(v), _np.asarray(f), None if q is None else _np.asarray(q),
                        None if n is None else _np.asarray(n), _os.fspath(path), bool(ascii))


_EXTRACT_OPTIONS = ("method", "quality", "macet_relax", "dc_solver", "dc_hermite", "dc_vertices",
                    "quads", "backend", "normals", "frame", "simplify", "check_intersections",
                    "allow_empty", "memory", "output", "ascii", "stats")
_FILE_OPTIONS = ("dims", "type", "spacing", "origin", "endian", "series")


def _refuse(given, applies):
    """ValueError naming the keywords given (``given``: name -> bool) that apply elsewhere."""
    names = [name for name, was_given in given.items() if was_given]
    if names:
        raise ValueError(f"{', '.join(names)} appl{'ies' if len(names) == 1 else 'y'} only "
                         f"{applies}")


_MAX_THREADS = 4096  # as the CLI's --threads: TBB fails past what it can start


def _check_threads(threads):
    if threads is not None and (isinstance(threads, bool)
                                or not isinstance(threads, _numbers.Integral)
                                or not 1 <= threads <= _MAX_THREADS):
        raise ValueError(f"threads must be an int from 1 to {_MAX_THREADS}, or None (every "
                         f"core), not {threads!r}")


def extract(source, iso=None, *, method="mc", quality="fast", macet_relax=0.0, dc_solver="mass",
            dc_hermite="central", dc_vertices="patch", quads=False, backend="auto",
            normals=False, frame="world", simplify=1.0, check_intersections=False,
            allow_empty=False, memory=None, output=None, ascii=False, stats=True, threads=None,
            progress=None, dims=None, type=None, spacing=None, origin=None, endian="little",
            series=None, direction=None):
    """Extract an isosurface, as ``isotile extract`` does (the same library pipeline).

    Parameters
    ----------
    source : path, Volume or (Z, Y, X) array
        Anything the CLI reads (a volume file, a DICOM or TIFF directory, ``field:NAME:N``), a
        ``Volume`` from ``read_volume`` (the same mesh as its path), or an array indexed
        [z, y, x] (``spacing``, ``origin`` and ``direction`` then describe it, in x, y, z).
    iso : float or "auto"
        The isovalue (samples >= iso are inside), or "auto": Otsu's threshold of the samples.
        Required except for procedural fields, which have their own (as in the CLI).
    method, quality, macet_relax, dc_solver, dc_hermite, dc_vertices, quads, backend, normals,
    frame, simplify, check_intersections, allow_empty, ascii
        The CLI's options of the same names (``--dc-solver`` is ``dc_solver``, ...), with its
        defaults and checks.
    memory : str or int, optional
        Out of core: each brick's working set within this many bytes ("256MiB", "2GB", or an
        int), the mesh streamed into ``output`` (binary .ply or .stl) as ``--memory`` does.
    output : path, optional
        Also write the mesh there (in core); required with ``memory``.
    stats : bool
        Measure the result: the dict of ``--stats`` (the same keys and values; "output" is None
        without an output file).
    threads : int, optional
        At most this many worker threads while the call runs (None: every core), as the
        process's limit (other isotile calls running meanwhile share it); the result does not
        depend on it.
    progress : callable, optional
        ``progress(stage, brick, bricks, fraction)`` during the run ("count", "extract",
        "simplify", ...); a false return value other than None cancels the run
        (``isotile.Cancelled``; a callback that returns nothing goes on) and an
        exception it raises cancels it and propagates. Ctrl-C raises KeyboardInterrupt within a
        fraction of a second at the library's next report; a cancelled run leaves no file.
    dims, type, spacing, origin, endian, series
        For files: the CLI's raw-input options (a tuple or the CLI's text). Arrays take
        ``spacing`` and ``origin`` (x, y, z) too, as a tuple or the same text.
    direction : 3x3, optional
        For arrays: the world direction of each index axis (columns).

    Returns
    -------
    Mesh
        In core: the mesh (in the world frame unless frame="grid") with its ``stats``.
    dict or None
        Out of core (``memory``): the stats; the mesh is in ``output``.

    Warns
    -----
    RuntimeWarning
        What the CLI says as ``isotile: warning:``, while the run goes on: a ``memory`` budget
        the surface overflows (the run goes above it; the mesh is exact), a grid so far from 0
        that float32 vertices snap to a coarse lattice, or with backend="auto" a GPU backend
        that failed (the CPU took over). Made an error by a
        warnings filter, it stops the run and leaves no file.
    """
    _check_threads(threads)
    if isinstance(simplify, bool):
        raise ValueError("simplify is the fraction of faces to keep, in (0, 1], not "
                         f"{simplify!r}")
    if isinstance(memory, bool):
        raise ValueError("memory must be a byte count (an int above 0) or a size such as "
                         f"'256MiB', not {memory!r}")
    if ascii and output is None:
        raise ValueError("ascii applies to the output file; give output")
    options = {"iso": iso}
    local = locals()
    for key in _EXTRACT_OPTIONS:
        options[key] = local[key]
    if options["output"] is not None:
        options["output"] = _os.fsdecode(_os.fspath(options["output"]))
    # Keywords that the kind of source has no use for are refused, not dropped.
    file_only = {"dims": dims is not None, "type": type is not None,
                 "endian": endian != "little", "series": series is not None}
    if isinstance(source, Volume):
        _refuse({"spacing": spacing is not None, "origin": origin is not None,
                 "direction": direction is not None, **file_only},
                "to a path or an array; a Volume has its own (read_volume(path, spacing=...) "
                "or Volume(samples, spacing=...))")
        if source._handle is not None:
            if source.samples is not source._read_samples:
                raise ValueError("this Volume's samples were replaced after read_volume, and its "
                                 "file's are what the run uses: wrap the new samples in "
                                 "Volume(samples, spacing=v.spacing, origin=v.origin, "
                                 "direction=v.direction)")
            if (tuple(source.spacing) != tuple(source._handle.spacing)
                    or tuple(source.origin) != tuple(source._handle.world_origin)
                    or not _same_matrix(source.direction, source._handle.direction)):
                raise ValueError("this Volume's spacing, origin or direction was changed after "
                                 "read_volume, and its file's are what the run uses: read it "
                                 "with read_volume(path, spacing=..., origin=...)")
            src = source._handle
        else:
            src = _readable(source.samples, "samples")
            options.update(spacing=source.spacing, origin=source.origin,
                           direction=source.direction, name=source.name)
    elif isinstance(source, (str, bytes, _os.PathLike)):
        _refuse({"direction": direction is not None},
                "to an array (a file's direction is its own)")
        src = _os.fsdecode(_os.fspath(source))
        options.update(_raw_options(dims, type, spacing, origin, endian, series))
    else:
        _refuse(file_only, "to files (an array's samples are given)")
        src = _readable(source, "source")
        options.update(spacing=spacing, origin=origin, direction=direction)
    mesh, stats_text = _isotile.run_pipeline(src, options, progress, threads)
    stats_dict = None if stats_text is None else _json.loads(stats_text)
    if mesh is None:
        return stats_dict
    return Mesh(*mesh, stats=stats_dict)
