# Type stubs of the isotile package (python/isotile/__init__.py holds the docstrings).
from typing import Literal, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

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
