"""Reading a reconstructed cloud (``cloud.ply``, field frame) for the evaluations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FormatError, Problem
from fieldapp.io import ply


def read_cloud(path: Path) -> tuple[NDArray[np.float64], NDArray[np.uint8] | None]:
    """Points (N, 3) float64 metres and colours (N, 3) uint8 (``None`` when the file has none).
    Raises :class:`FormatError` when the file is missing, unreadable or holds no points."""
    if not path.is_file():
        raise FormatError([Problem(str(path), "", "file is missing")])
    with path.open("rb") as file:
        if file.read(4) != b"ply\n":
            raise FormatError([Problem(str(path), "", "not a PLY file")])
    try:
        vertices = ply.read_ply(path)
        points = ply.points_of(vertices, str(path))
    except ply.PlyError as error:
        raise FormatError([Problem(str(path), "", str(error).removeprefix(f"{path}: "))]) from None
    if len(points) == 0:
        raise FormatError([Problem(str(path), "", "no points could be read")])
    if not np.isfinite(points).all():
        raise FormatError([Problem(str(path), "vertex", "non-finite coordinates")])
    return points, ply.colors_of(vertices)
