"""A coloured point cloud: points with their RGB colours, kept together through every stage."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, transform_points


@dataclass(frozen=True)
class Cloud:
    """``points``: (N, 3) float64 metres in the frame the holder names; ``colors``: (N, 3) uint8."""

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]

    def __post_init__(self) -> None:
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise ValueError(f"points must be (N, 3), got {self.points.shape}")
        if self.colors.shape != self.points.shape:
            raise ValueError(f"colors {self.colors.shape} do not match points {self.points.shape}")

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @classmethod
    def empty(cls) -> Cloud:
        return cls(np.zeros((0, 3)), np.zeros((0, 3), np.uint8))

    def select(self, mask_or_index: NDArray[np.bool_] | NDArray[np.intp]) -> Cloud:
        """The points picked by a boolean mask or an index array."""
        return Cloud(self.points[mask_or_index], self.colors[mask_or_index])

    def transformed(self, T_target_source: Matrix4) -> Cloud:
        """This cloud (in the source frame) expressed in the target frame."""
        return Cloud(transform_points(T_target_source, self.points), self.colors)

    @staticmethod
    def concatenate(clouds: list[Cloud]) -> Cloud:
        if not clouds:
            return Cloud.empty()
        return Cloud(
            np.concatenate([c.points for c in clouds]), np.concatenate([c.colors for c in clouds])
        )
