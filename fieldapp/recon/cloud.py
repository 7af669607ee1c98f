"""A coloured point cloud: points with their RGB colours (and which are mixed pixels), kept
together through every stage."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, transform_points


@dataclass(frozen=True)
class Cloud:
    """``points``: (N, 3) float64 metres in the frame the holder names; ``colors``: (N, 3) uint8;
    ``mixed``: (N,) bool, which points were read from mixed pixels (a time-of-flight pixel across
    a depth edge, with no colour of its own: a depth between a leaf's edge and what lies behind
    it, :func:`~fieldapp.recon.scans.mixed_pixels`), or None where none were looked for. Such
    points hold a plant together but do not set its width (:func:`width_points`)."""

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    mixed: NDArray[np.bool_] | None = None

    def __post_init__(self) -> None:
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {self.points.shape}")
        if self.colors.shape != self.points.shape:
            raise ValueError(f"colors {self.colors.shape} do not match points {self.points.shape}")
        if self.mixed is not None and self.mixed.shape != (len(self.points),):
            raise ValueError(f"mixed {self.mixed.shape} does not match points {self.points.shape}")

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @classmethod
    def empty(cls) -> Cloud:
        return cls(np.zeros((0, 3)), np.zeros((0, 3), np.uint8))

    def select(self, mask_or_index: NDArray[np.bool_] | NDArray[np.intp]) -> Cloud:
        """The points picked by a boolean mask or an index array."""
        mixed = None if self.mixed is None else self.mixed[mask_or_index]
        return Cloud(self.points[mask_or_index], self.colors[mask_or_index], mixed)

    def transformed(self, T_target_source: Matrix4) -> Cloud:
        """This cloud (in the source frame) expressed in the target frame."""
        return Cloud(transform_points(T_target_source, self.points), self.colors, self.mixed)

    def mixed_mask(self) -> NDArray[np.bool_]:
        """(N,) which points are mixed pixels; none where none were looked for."""
        return np.zeros(len(self), dtype=bool) if self.mixed is None else self.mixed

    @staticmethod
    def concatenate(clouds: list[Cloud]) -> Cloud:
        if not clouds:
            return Cloud.empty()
        return Cloud(
            np.concatenate([c.points for c in clouds]),
            np.concatenate([c.colors for c in clouds]),
            joined_mixed(clouds),
        )


def joined_mixed(clouds: list[Cloud]) -> NDArray[np.bool_] | None:
    """The ``mixed`` flags of ``clouds`` end to end (none for a cloud without them), or None
    when no cloud has them."""
    if all(c.mixed is None for c in clouds):
        return None
    return np.concatenate([c.mixed_mask() for c in clouds])


def width_points(cloud: Cloud) -> NDArray[np.float64]:
    """The points that set a plant's width: all but the mixed pixels, or all of them where
    every point is one (a plant is never left without a width)."""
    if cloud.mixed is None or not cloud.mixed.any() or cloud.mixed.all():
        return cloud.points
    return cloud.points[~cloud.mixed]
