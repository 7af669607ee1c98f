"""What is true about a simulated plant's organs: every leaf's length, width, area, angle,
azimuth and insertion height, and the stem's diameter (definitions in docs/TRAITS.md).

Read from the finished mesh (leaning, scaled, settled on the soil): the stem is a tapering
prism of rings of ``PlantMesh.stem_sides`` vertices (:func:`devices.sim.plants._stem`), a leaf a
ribbon of ``PlantMesh.section_vertices`` vertices per section (three for the first model, five
for the ``irregular`` one), its midrib the middle one, its flattened width the length of the
section from margin to margin.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.sim.plants import STEM_PART, PlantMesh

BASE_CHORD_M = 0.05
"""The midrib's direction at its base: the chord from the collar to the midrib point this far
along it (or the tip of a shorter leaf)."""

STEM_SAMPLES = 21
"""Heights at which the stem's diameter is taken between the ground and the lowest leaf."""


def organ_truth(mesh: PlantMesh) -> dict[str, Any]:
    """``{"stem_diameter_mm", "leaf_count", "leaf_area_cm2", "leaves": [...]}`` of ``mesh``;
    leaves from the bottom, each with ``leaf_id``, ``length_cm`` (midrib, collar to tip),
    ``max_width_cm`` (flattened), ``area_cm2`` (one side, the flattened width integrated along
    the midrib from the collar), ``angle_from_stem_deg``, ``azimuth_deg`` (field frame,
    counter-clockwise from +x) and ``insertion_height_cm`` (above the ground at the foot)."""
    if mesh.organ_of_vertex is None:
        raise ValueError("the plant mesh does not say which vertex belongs to which organ")
    centres, radii = _stem_rings(mesh)
    axis = centres[-1] - centres[0]
    axis /= np.linalg.norm(axis)
    leaves = []
    for k in range(int(mesh.organ_of_vertex.max()) + 1):
        leaves.append(_leaf_truth(mesh, k, centres, radii, axis))
    leaves.sort(key=lambda leaf: leaf["insertion_height_cm"])
    for number, leaf in enumerate(leaves, start=1):
        leaf["leaf_id"] = number
    lowest_m = min((leaf["insertion_height_cm"] for leaf in leaves), default=0.0) / 100.0
    heights = mesh.base_m[2] + np.linspace(0.0, lowest_m, STEM_SAMPLES)
    girth = mesh.stem_sides * np.sin(np.pi / mesh.stem_sides) / np.pi
    diameters = 2.0 * np.interp(heights, centres[:, 2], radii) * girth
    return {
        "stem_diameter_mm": round(1000.0 * float(np.median(diameters)), 3),
        "leaf_count": len(leaves),
        "leaf_area_cm2": round(sum(leaf["area_cm2"] for leaf in leaves), 3),
        "leaves": [{"leaf_id": leaf.pop("leaf_id"), **leaf} for leaf in leaves],
    }


def _stem_rings(mesh: PlantMesh) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Centres (R, 3) and circumscribed radii (R,) of the stem's rings, bottom first."""
    stem = mesh.vertices_m[mesh.organ_of_vertex == STEM_PART].reshape(-1, mesh.stem_sides, 3)
    centres = stem.mean(axis=1)
    radii = np.linalg.norm(stem - centres[:, None, :], axis=2).mean(axis=1)
    return centres, radii


def _leaf_truth(
    mesh: PlantMesh,
    k: int,
    centres: NDArray[np.float64],
    radii: NDArray[np.float64],
    axis: NDArray[np.float64],
) -> dict[str, Any]:
    chosen = np.flatnonzero(mesh.organ_of_vertex == k)
    across = mesh.section_vertices
    sections = mesh.vertices_m[chosen].reshape(-1, across, 3)  # (S, margin to margin, xyz)
    middle = sections[:, across // 2]
    midrib = _from_collar(middle, centres, radii, axis)
    collar, tip = midrib[0], midrib[-1]
    width = np.linalg.norm(np.diff(sections, axis=1), axis=2).sum(axis=1)  # flattened
    section_s = _arc(middle)
    collar_s = section_s[-1] - _arc_length(midrib)
    s = np.concatenate([[collar_s], section_s[section_s > collar_s]])
    area = np.trapezoid(np.interp(s, section_s, width), s)
    return {
        "leaf_id": 0,
        "length_cm": round(100.0 * _arc_length(midrib), 3),
        "max_width_cm": round(100.0 * float(width.max()), 3),
        "area_cm2": round(1e4 * float(area), 3),
        "angle_from_stem_deg": round(angle_from_axis_deg(midrib, axis), 3),
        "azimuth_deg": round(azimuth_deg(tip - collar), 3),
        "insertion_height_cm": round(100.0 * float(collar[2] - mesh.base_m[2]), 3),
    }


def _from_collar(
    midrib: NDArray[np.float64],
    centres: NDArray[np.float64],
    radii: NDArray[np.float64],
    axis: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The midrib (S, 3) from where it leaves the stem's surface (the collar), finely resampled
    so that the collar falls within 0.1 mm."""
    fine = resample(midrib, 1e-4)
    offset = fine - centres[0]
    along = offset @ axis
    radial = np.linalg.norm(offset - along[:, None] * axis, axis=1)
    inside = radial < np.interp(fine[:, 2], centres[:, 2], radii)
    start = int(np.argmin(inside)) if inside[0] else 0
    return fine[start:]


def resample(polyline: NDArray[np.float64], step_m: float) -> NDArray[np.float64]:
    """``polyline`` (P, 3) resampled every ``step_m`` along it, both ends kept."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))])
    at = np.append(np.arange(0.0, s[-1], step_m), s[-1])
    return np.stack([np.interp(at, s, polyline[:, i]) for i in range(3)], axis=1)


def _arc(polyline: NDArray[np.float64]) -> NDArray[np.float64]:
    """(P,) arc length along ``polyline`` (P, 3) at each of its points."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))])


def _arc_length(polyline: NDArray[np.float64]) -> float:
    return float(np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum())


def angle_from_axis_deg(midrib: NDArray[np.float64], axis: NDArray[np.float64]) -> float:
    """Angle between ``axis`` (3,) (the stem, upward) and the chord from the midrib's first
    point (the collar) to its point :data:`BASE_CHORD_M` along it (P, 3)."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(midrib, axis=0), axis=1))])
    end = np.array([np.interp(min(BASE_CHORD_M, s[-1]), s, midrib[:, i]) for i in range(3)])
    chord = end - midrib[0]
    cosine = float(chord @ axis) / max(float(np.linalg.norm(chord)), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def azimuth_deg(direction: NDArray[np.float64]) -> float:
    """Azimuth of ``direction``'s horizontal part, degrees in [0, 360) from +x towards +y."""
    return float(np.degrees(np.arctan2(direction[1], direction[0])) % 360.0)
