"""What the per-plant inspector draws, as plain arrays (no Qt, so a worker can build it): the
plant's points coloured by organ (the stem one colour, each leaf its own), the vertical line
of its height and the circle of its width, both as ``plants.csv`` defines them
(docs/TRAITS.md), and its leaves.

The height line stands at the plant's foot, from the local ground up to the highest supported
point (the point :func:`fieldapp.recon.traits.robust_top_z_m` finds, with the reconstruction's
settings); the local ground is that top less the height. The width circle is the smallest
circle enclosing the plant's projection (:func:`fieldapp.recon.traits.smallest_enclosing_circle`),
its mixed pixels left out as the reconstruction leaves them out
(:func:`fieldapp.recon.cloud.width_points`), drawn on the local ground. SciPy (which those
use) is imported when a plant is first drawn, not with the GUI (``tests/ui/test_startup.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.recon.cloud import Cloud, width_points
from fieldapp.recon.outputs import read_labelled_ply
from fieldapp.recon.settings import PlantSettings
from ui.results.data import PlotResults

STEM_RGB = (0.55, 0.33, 0.16)
WHORL_RGB = (0.85, 0.62, 0.30)
OTHER_RGB = (0.6, 0.6, 0.6)
LEAF_RGB = (
    (0.12, 0.47, 0.71),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.09, 0.75, 0.81),
    (0.89, 0.47, 0.76),
    (0.74, 0.74, 0.13),
    (1.00, 0.50, 0.05),
)
"""One colour per leaf, by leaf number (repeating after eight leaves)."""
DIM = 0.4
CIRCLE_VERTICES = 96


def leaf_rgb(leaf_id: int) -> tuple[float, float, float]:
    return LEAF_RGB[(leaf_id - 1) % len(LEAF_RGB)]


def height_definition(settings: PlantSettings) -> str:
    """How the height is measured (``fieldapp.recon.traits.robust_top_z_m``), for the caption."""
    from fieldapp.recon.traits import TOP_LINK_M, TOP_REACH_M

    return (
        f"highest point from which a chain of points, each within {1000 * TOP_LINK_M:g} mm of "
        f"the next, leads {100 * TOP_REACH_M:g} cm down into the plant, above the local ground "
        "at the foot"
    )


WIDTH_DEFINITION = "diameter of the smallest circle enclosing the plant's ground projection"


@dataclass(frozen=True)
class PlantDrawing:
    plant: int
    points_m: NDArray[np.float32]
    """(N, 3) field frame."""
    colors: NDArray[np.float32]
    """(N, 4) RGBA in 0-1, by organ."""
    organ: NDArray[np.uint8]
    """(N,) organ code (:mod:`fieldapp.recon.organs`), 0 everywhere when not measured."""
    leaf_id: NDArray[np.uint8]
    """(N,) leaf number from the bottom, 0 off the leaves."""
    height_line_m: NDArray[np.float64]
    """(2, 3) from the local ground at the foot up to the plant's top."""
    width_circle_m: NDArray[np.float64]
    """(CIRCLE_VERTICES + 1, 3) closed circle on the local ground."""
    fan_xy: NDArray[np.float64]
    """(2,) unit horizontal direction the leaves spread along most (a maize plant's leaves
    stand in about one plane): the views look across it, and the side view draws along it."""
    height_cm: float
    width_cm: float
    caption: str
    """The traits drawn, with their definitions named."""
    leaves: list[dict[str, Any]]
    """The plant's ``leaves.csv`` rows, from the bottom."""

    @property
    def view_azimuth_deg(self) -> float:
        """The camera's azimuth (from +x, counter-clockwise) looking across the leaves."""
        return float(np.degrees(np.arctan2(self.fan_xy[1], self.fan_xy[0]))) + 90.0

    def along_fan_m(self, points_m: NDArray[np.floating[Any]]) -> NDArray[np.float64]:
        """(N,) horizontal position of ``points_m`` (N, 3) along the fan, from the foot."""
        return (np.asarray(points_m[:, :2], np.float64) - self.height_line_m[0, :2]) @ self.fan_xy

    def colors_for_leaf(self, leaf_id: int | None) -> NDArray[np.float32]:
        """(N, 4) the colours with leaf ``leaf_id`` alone at full strength (None: all)."""
        if leaf_id is None:
            return self.colors
        colors = self.colors.copy()
        colors[self.leaf_id != leaf_id, :3] *= DIM
        return colors


def organ_colors(organ: NDArray[np.uint8], leaf_id: NDArray[np.uint8]) -> NDArray[np.float32]:
    """(N, 4) RGBA: stem, whorl, each leaf and the rest in their colours."""
    from fieldapp.recon.organs import ORGAN_LEAF, ORGAN_STEM, ORGAN_WHORL  # SciPy: when used

    rgba = np.ones((len(organ), 4), np.float32)
    rgba[:, :3] = OTHER_RGB
    rgba[organ == ORGAN_STEM, :3] = STEM_RGB
    rgba[organ == ORGAN_WHORL, :3] = WHORL_RGB
    for leaf in np.unique(leaf_id[organ == ORGAN_LEAF]):
        rgba[(organ == ORGAN_LEAF) & (leaf_id == leaf), :3] = leaf_rgb(int(leaf))
    return rgba


def fan_direction(points_xy_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """(2,) unit direction of the largest spread of ``points_xy_m`` (N, 2)."""
    if len(points_xy_m) < 2:
        return np.array([1.0, 0.0])
    _, vectors = np.linalg.eigh(np.cov(points_xy_m.T))
    return np.asarray(vectors[:, -1], np.float64)


def plant_drawing(
    results: PlotResults, plant: int, settings: PlantSettings | None = None
) -> PlantDrawing:
    """The drawing of ``plant``: its labelled PLY (``plants/<plant>.ply``) when the results
    folder has one, else its cloud in memory (organs unknown). Raises ``KeyError`` for a plant
    not in ``results``, :class:`FieldappError` for a plant without points or a bad PLY."""
    from fieldapp.recon.traits import robust_top_z_m, smallest_enclosing_circle  # SciPy

    settings = settings or PlantSettings()
    record = results.plant(plant)
    cloud, organ, leaf = _labelled_points(results, plant)
    points = cloud.points
    top_z = robust_top_z_m(points, settings.top_support_points, settings.top_support_radius_m)
    ground_z = top_z - record.height_cm / 100.0
    circle = smallest_enclosing_circle(width_points(cloud)[:, :2])  # as it was measured
    angles = np.linspace(0.0, 2.0 * np.pi, CIRCLE_VERTICES + 1)
    centre = np.array([circle.centre_x_m, circle.centre_y_m, ground_z])
    ring = centre + circle.radius_m * np.c_[np.cos(angles), np.sin(angles), 0.0 * angles]
    leaves = results.leaves.get(plant, [])
    return PlantDrawing(
        plant=plant,
        points_m=points.astype(np.float32),
        colors=organ_colors(organ, leaf),
        organ=organ,
        leaf_id=leaf,
        height_line_m=np.array(
            [[record.x_m, record.y_m, ground_z], [record.x_m, record.y_m, top_z]]
        ),
        width_circle_m=ring,
        fan_xy=fan_direction(points[:, :2]),
        height_cm=record.height_cm,
        width_cm=record.width_cm,
        caption=(
            f"plant {plant}: height {record.height_cm:.1f} cm ({height_definition(settings)}); "
            f"width {record.width_cm:.1f} cm ({WIDTH_DEFINITION}); {len(leaves)} leaves"
        ),
        leaves=sorted(leaves, key=lambda row: row["leaf_id"]),
    )


def _labelled_points(
    results: PlotResults, plant: int
) -> tuple[Cloud, NDArray[np.uint8], NDArray[np.uint8]]:
    path: Path = results.results_dir / "plants" / f"{plant}.ply"
    labels = None
    if path.is_file():
        cloud, labels = read_labelled_ply(path)
    else:
        cloud = results.plant_clouds.get(plant, Cloud.empty())
    if len(cloud) == 0:
        raise FieldappError(f"plant {plant} has no points ({path} missing or empty)")
    if labels is not None:
        return cloud, labels.organ, labels.leaf_id
    none = np.zeros(len(cloud), np.uint8)
    return cloud, none, none
