"""Point clouds with per-point scalar fields: LAZ 1.4 (laspy) and binary PLY.

Every point of ``cloud.ply`` gets the id of the plant whose ``plants/<id>.ply`` holds it (0:
none) and an organ label. Organs are not segmented yet (issue 21): every point's ``organ`` is
0, "unknown"; the field is there so files keep their layout when organs come.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.io.durable import write_bytes_durably
from fieldapp.io.ply import ply_bytes
from fieldapp.recon.outputs import read_ply

ORGANS = {0: "unknown", 1: "stem", 2: "leaf", 3: "soil"}
"""Organ codes of the ``organ`` field (only 0 is written until organs are segmented)."""
LAS_LOW_VEGETATION = 3
LAS_UNCLASSIFIED = 1


@dataclass(frozen=True)
class LabelledCloud:
    """``points`` (N, 3) float64 m, field frame; ``colors`` (N, 3) uint8; ``plant_id`` (N,)
    uint32 (0: no plant); ``organ`` (N,) uint8 (codes of :data:`ORGANS`)."""

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    plant_id: NDArray[np.uint32]
    organ: NDArray[np.uint8]


def _keys(points: NDArray[np.float64]) -> NDArray[np.void]:
    """One comparable key per point: its float32 coordinates as stored in the PLY."""
    packed = np.ascontiguousarray(points.astype("<f4"))
    return packed.view(np.dtype((np.void, 12))).ravel()


def labelled_cloud(results: Path) -> LabelledCloud:
    """``cloud.ply`` of a results folder with each point's plant id from ``plants/``."""
    path = results / "cloud.ply"
    if not path.is_file():
        raise FieldappError(f"{path}: file is missing (is this a results folder?)")
    try:
        cloud = read_ply(path)
    except ValueError as error:
        raise FieldappError(f"{path}: not a fieldapp cloud ({error})") from None
    plant_id = np.zeros(len(cloud), np.uint32)
    keys = _keys(cloud.points)
    order = np.argsort(keys)
    for plant_path in sorted((results / "plants").glob("*.ply")):
        if not plant_path.stem.isdigit():
            continue
        plant_keys = _keys(read_ply(plant_path).points)
        at = np.searchsorted(keys[order], plant_keys)
        at = np.clip(at, 0, len(keys) - 1)
        found = keys[order][at] == plant_keys
        plant_id[order[at[found]]] = int(plant_path.stem)
    return LabelledCloud(cloud.points, cloud.colors, plant_id, np.zeros(len(cloud), np.uint8))


def write_laz(path: Path, cloud: LabelledCloud) -> None:
    """LAS 1.4, point format 7 (xyz, RGB), ``plant_id`` (uint32) and ``organ`` (uint8) extra
    dimensions, plant points classified 3 (low vegetation); compressed when ``path`` ends in
    ``.laz``. Coordinates to 0.1 mm, in the local field frame (no CRS)."""
    import laspy  # type: ignore[import-untyped, import-not-found, unused-ignore]

    header = laspy.LasHeader(point_format=7, version="1.4")
    header.add_extra_dims(
        [
            laspy.ExtraBytesParams("plant_id", np.uint32, "plant id (0: none)"),
            laspy.ExtraBytesParams("organ", np.uint8, "0 unknown 1 stem 2 leaf 3 soil"),
        ]
    )
    header.scales = np.array([0.0001, 0.0001, 0.0001])
    header.offsets = cloud.points.min(axis=0) if len(cloud.points) else np.zeros(3)
    header.system_identifier = "fieldapp"
    header.generating_software = "fieldapp export"
    las = laspy.LasData(header)
    las.x, las.y, las.z = (cloud.points[:, i] for i in range(3))
    for i, name in enumerate(("red", "green", "blue")):
        las[name] = cloud.colors[:, i].astype(np.uint16) * 257
    las.classification = np.where(cloud.plant_id > 0, LAS_LOW_VEGETATION, LAS_UNCLASSIFIED)
    las.plant_id = cloud.plant_id
    las.organ = cloud.organ
    buffer = io.BytesIO()
    las.write(buffer, do_compress=path.suffix.lower() == ".laz")
    write_bytes_durably(path, buffer.getvalue())


_PLY_VERTEX = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("scalar_plant_id", "<u4"),
        ("scalar_organ", "u1"),
    ]
)


def ply_with_fields(cloud: LabelledCloud) -> bytes:
    """Binary little-endian PLY: x, y, z (float), RGB (uchar), ``scalar_plant_id`` (uint),
    ``scalar_organ`` (uchar). The ``scalar_`` prefix is CloudCompare's own: it loads them as
    scalar fields named ``plant_id`` and ``organ`` without asking (checked with CloudCompare
    2.11's command line); other readers see the properties as they are named."""
    vertices = np.empty(len(cloud.points), _PLY_VERTEX)
    for i, name in enumerate("xyz"):
        vertices[name] = cloud.points[:, i]
    for i, name in enumerate(("red", "green", "blue")):
        vertices[name] = cloud.colors[:, i]
    vertices["scalar_plant_id"], vertices["scalar_organ"] = cloud.plant_id, cloud.organ
    return ply_bytes(
        vertices, ["fieldapp export: field frame, metres; organ 0 unknown 1 stem 2 leaf 3 soil"]
    )
