# Type stubs of the isotile package (python/isotile/__init__.py holds the docstrings).
import os
from typing import Any, Callable, Dict, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

PathLike = Union[str, os.PathLike]

def marching_cubes(
    volume: npt.NDArray[np.generic],
    level: Optional[float] = ...,
    *,
    spacing: Sequence[float] = ...,
    gradient_direction: Literal["descent", "ascent"] = ...,
    step_size: int = ...,
    allow_degenerate: bool = ...,
    method: Literal["lewiner", "lorensen", "mc", "macet", "dc"] = ...,
    mask: Optional[npt.NDArray[np.bool_]] = ...,
    quality: Literal["fast", "max"] = ...,
    backend: Literal["cpu", "gs", "hp", "auto"] = ...,
    threads: Optional[int] = ...,
    normals: bool = ...,
) -> Tuple[
    npt.NDArray[np.float32],
    npt.NDArray[np.int32],
    Optional[npt.NDArray[np.float32]],
    npt.NDArray[np.float32],
]: ...
def quality(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    *,
    check_intersections: bool = ...,
    threads: Optional[int] = ...,
) -> dict: ...
def simplify(
    vertices: npt.ArrayLike,
    triangles: npt.ArrayLike,
    /,
    *,
    ratio: Optional[float] = ...,
    faces: Optional[int] = ...,
    max_error: Optional[float] = ...,
    min_quality: float = ...,
    relax: bool = ...,
    threads: Optional[int] = ...,
) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.int32]]: ...
def backends() -> dict: ...

class Cancelled(Exception): ...
class NoSurface(ValueError, RuntimeError): ...

class Volume:
    samples: npt.NDArray[np.generic]
    spacing: Tuple[float, float, float]
    origin: Tuple[float, float, float]
    direction: Optional[List[List[float]]]
    name: str
    def __init__(
        self,
        samples: npt.ArrayLike,
        spacing: Sequence[float] = ...,
        origin: Sequence[float] = ...,
        direction: Optional[Sequence[Sequence[float]]] = ...,
    ) -> None: ...

class Mesh:
    vertices: npt.NDArray[np.float32]
    faces: npt.NDArray[np.integer]
    quads: npt.NDArray[np.integer]
    normals: Optional[npt.NDArray[np.float32]]
    stats: Optional[Dict[str, Any]]
    def __init__(
        self,
        vertices: npt.ArrayLike,
        faces: npt.ArrayLike,
        quads: Optional[npt.ArrayLike] = ...,
        normals: Optional[npt.ArrayLike] = ...,
        stats: Optional[Dict[str, Any]] = ...,
    ) -> None: ...
    def save(self, path: PathLike, *, ascii: bool = ...) -> None: ...

def read_volume(
    path: PathLike,
    *,
    dims: Optional[Union[str, Sequence[int]]] = ...,
    type: Optional[str] = ...,
    spacing: Optional[Union[str, Sequence[float]]] = ...,
    origin: Optional[Union[str, Sequence[float]]] = ...,
    endian: Literal["little", "big"] = ...,
    series: Optional[str] = ...,
) -> Volume: ...
def read_mesh(path: PathLike) -> Mesh: ...
def write_mesh(
    path: PathLike,
    mesh: Union[Mesh, Tuple[npt.ArrayLike, npt.ArrayLike]],
    *,
    ascii: bool = ...,
) -> None: ...
def extract(
    source: Union[PathLike, Volume, npt.NDArray[np.generic]],
    iso: Optional[Union[float, Literal["auto"]]] = ...,
    *,
    method: Literal["mc", "macet", "dc"] = ...,
    quality: Literal["fast", "max"] = ...,
    macet_relax: float = ...,
    dc_solver: Literal["mass", "particle", "qef"] = ...,
    dc_hermite: Literal["central", "eno"] = ...,
    dc_vertices: Literal["patch", "cell"] = ...,
    quads: bool = ...,
    backend: Literal["cpu", "gs", "hp", "auto"] = ...,
    normals: bool = ...,
    frame: Literal["world", "grid"] = ...,
    simplify: float = ...,
    check_intersections: bool = ...,
    allow_empty: bool = ...,
    memory: Optional[Union[str, int]] = ...,
    output: Optional[PathLike] = ...,
    ascii: bool = ...,
    stats: bool = ...,
    threads: Optional[int] = ...,
    progress: Optional[Callable[[str, int, int, float], Any]] = ...,
    dims: Optional[Union[str, Sequence[int]]] = ...,
    type: Optional[str] = ...,
    spacing: Optional[Union[str, Sequence[float]]] = ...,
    origin: Optional[Union[str, Sequence[float]]] = ...,
    endian: Literal["little", "big"] = ...,
    series: Optional[str] = ...,
    direction: Optional[Sequence[Sequence[float]]] = ...,
) -> Union[Mesh, Optional[Dict[str, Any]]]: ...
