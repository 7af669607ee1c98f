"""Point clouds with per-point scalar fields: LAZ 1.4 (laspy) and binary PLY.

Every point of ``cloud.ply`` carries what the results folder records of it: the id of its
plant (0: none), its organ (:mod:`fieldapp.recon.organs` codes: 0 none, 1 stem, 2 leaf, 3 whorl),
its leaf (0: not a leaf) and whether it was read from a mixed pixel (1: a depth between a leaf's
edge and what lies behind it, kept in its plant but not used for its width). These come from
``cloud.ply``'s own labels; a cloud written without them (organs not measured, an imported
cloud) gets its plant ids from ``plants/<id>.ply`` and 0 for the rest.
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
from fieldapp.recon.organs import ORGAN_LEAF, ORGAN_NONE, ORGAN_STEM, ORGAN_WHORL
from fieldapp.recon.outputs import read_results_cloud

ORGANS = {ORGAN_NONE: "none", ORGAN_STEM: "stem", ORGAN_LEAF: "leaf", ORGAN_WHORL: "whorl"}
"""Organ codes of the ``organ`` field: those of the organ step (0 where organs were not
measured, or the point is no plant's)."""
ORGAN_CODES_TEXT = " ".join(f"{code} {name}" for code, name in sorted(ORGANS.items()))
"""The codes as the files describe them, "0 none 1 stem 2 leaf 3 whorl" (a LAS extra
dimension's description: 32 bytes at most)."""
LAS_LOW_VEGETATION = 3
LAS_UNCLASSIFIED = 1


@dataclass(frozen=True)
class LabelledCloud:
    """``points`` (N, 3) float64 m, field frame; ``colors`` (N, 3) uint8; ``plant_id`` (N,)
    uint32 (0: no plant); ``organ`` (N,) uint8 (codes of :data:`ORGANS`); ``leaf_id`` (N,)
    uint8 (0: not a leaf); ``mixed`` (N,) uint8 (1: read from a mixed pixel)."""

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    plant_id: NDArray[np.uint32]
    organ: NDArray[np.uint8]
    leaf_id: NDArray[np.uint8]
    mixed: NDArray[np.uint8]


def labelled_cloud(results: Path) -> LabelledCloud:
    """``cloud.ply`` of a results folder with each point's labels (module docstring;
    :func:`~fieldapp.recon.outputs.read_results_cloud`)."""
    path = results / "cloud.ply"
    try:
        cloud, labels = read_results_cloud(results)
    except FileNotFoundError:
        raise FieldappError(f"{path}: file is missing (is this a results folder?)") from None
    except ValueError as error:
        raise FieldappError(f"{path}: not a fieldapp cloud ({error})") from None
    return LabelledCloud(
        cloud.points,
        cloud.colors,
        labels.plant_id.astype(np.uint32),
        labels.organ,
        labels.leaf_id,
        cloud.mixed_mask().astype(np.uint8),
    )


def write_laz(path: Path, cloud: LabelledCloud) -> None:
    """LAS 1.4, point format 7 (xyz, RGB), ``plant_id`` (uint32), ``organ``, ``leaf_id`` and
    ``mixed`` (uint8) extra dimensions, plant points classified 3 (low vegetation); compressed
    when ``path`` ends in ``.laz``. Coordinates to 0.1 mm, in the local field frame (no CRS)."""
    import laspy  # type: ignore[import-untyped, import-not-found, unused-ignore]

    header = laspy.LasHeader(point_format=7, version="1.4")
    header.add_extra_dims(
        [
            laspy.ExtraBytesParams("plant_id", np.uint32, "plant id (0: none)"),
            laspy.ExtraBytesParams("organ", np.uint8, ORGAN_CODES_TEXT),
            laspy.ExtraBytesParams("leaf_id", np.uint8, "leaf from the bottom (0: none)"),
            laspy.ExtraBytesParams("mixed", np.uint8, "1: mixed pixel, not in width"),
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
    las.leaf_id = cloud.leaf_id
    las.mixed = cloud.mixed
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
        ("scalar_leaf_id", "u1"),
        ("scalar_mixed", "u1"),
    ]
)


def ply_with_fields(cloud: LabelledCloud) -> bytes:
    """Binary little-endian PLY: x, y, z (float), RGB (uchar), ``scalar_plant_id`` (uint),
    ``scalar_organ``, ``scalar_leaf_id`` and ``scalar_mixed`` (uchar). The ``scalar_`` prefix
    is CloudCompare's own: it loads them as scalar fields named ``plant_id``, ``organ``,
    ``leaf_id`` and ``mixed`` without asking (checked with CloudCompare 2.11's command line
    for ``plant_id`` and ``organ``, before the other two were added); other readers see the
    properties as they are named."""
    vertices = np.empty(len(cloud.points), _PLY_VERTEX)
    for i, name in enumerate("xyz"):
        vertices[name] = cloud.points[:, i]
    for i, name in enumerate(("red", "green", "blue")):
        vertices[name] = cloud.colors[:, i]
    vertices["scalar_plant_id"], vertices["scalar_organ"] = cloud.plant_id, cloud.organ
    vertices["scalar_leaf_id"], vertices["scalar_mixed"] = cloud.leaf_id, cloud.mixed
    return ply_bytes(
        vertices,
        [
            f"fieldapp export: field frame, metres; organ {ORGAN_CODES_TEXT}; "
            "leaf_id 0 none; mixed 1 = mixed pixel, not in the width"
        ],
    )
