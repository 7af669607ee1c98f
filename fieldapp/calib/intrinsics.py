"""Intrinsics by Zhang's method from checkerboard images, with per-view quality and advice."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from devices.camera.frames import Intrinsics
from fieldapp.calib.board import Board, detect_corners
from fieldapp.errors import FieldappError

MIN_VIEWS = 3
RECOMMENDED_VIEWS = 10
COVERAGE_GRID = 8


@dataclass
class ViewResult:
    """One image's part in the calibration."""

    name: str
    found: bool
    error_px: float | None = None
    rejected: str | None = None


@dataclass
class IntrinsicsResult:
    intrinsics: Intrinsics
    rms_px: float
    views: list[ViewResult]
    coverage: float
    """Fraction of the image's cells (8 x 8 grid) in which corners were seen."""
    coverage_map: NDArray[np.int32]
    """(8, 8) counts of corners per cell, row 0 at the top of the image."""
    warnings: list[str] = field(default_factory=list)

    @property
    def used(self) -> list[ViewResult]:
        return [v for v in self.views if v.found and v.rejected is None]


def read_calibration_image(path: Path) -> NDArray[np.generic]:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise FieldappError(f"{path}: not a readable image")
    return np.asarray(image)


def coverage_of(
    corner_sets: Sequence[NDArray[np.float32]], size: tuple[int, int]
) -> NDArray[np.int32]:
    """(8, 8) counts of corners per image cell; ``size`` is (width, height)."""
    counts = np.zeros((COVERAGE_GRID, COVERAGE_GRID), np.int32)
    for corners in corner_sets:
        cols = np.clip((corners[:, 0] / size[0] * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
        rows = np.clip((corners[:, 1] / size[1] * COVERAGE_GRID).astype(int), 0, COVERAGE_GRID - 1)
        np.add.at(counts, (rows, cols), 1)
    return counts


def missing_regions(counts: NDArray[np.int32]) -> list[str]:
    """Names of the image regions (3 x 3) where no corner was seen."""
    names = [
        ["top-left", "top", "top-right"],
        ["left", "centre", "right"],
        ["bottom-left", "bottom", "bottom-right"],
    ]
    edges = np.linspace(0, COVERAGE_GRID, 4).astype(int)
    return [
        names[i][j]
        for i in range(3)
        for j in range(3)
        if counts[edges[i] : edges[i + 1], edges[j] : edges[j + 1]].sum() == 0
    ]


def _solve(
    corner_sets: list[NDArray[np.float32]], board: Board, size: tuple[int, int], fix_aspect: bool
) -> tuple[float, NDArray[np.float64], NDArray[np.float64], list[float]]:
    objects = [board.object_points_m().astype(np.float32)] * len(corner_sets)
    images = [c.reshape(-1, 1, 2) for c in corner_sets]
    flags = cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect else 0
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        objects, images, size, np.eye(3), None, flags=flags
    )
    errors = []
    for obj, img, r, t in zip(objects, images, rvecs, tvecs, strict=True):
        projected, _ = cv2.projectPoints(obj, r, t, K, dist)
        errors.append(float(np.sqrt(np.mean(np.sum((projected - img) ** 2, axis=2)))))
    return float(rms), K, dist.ravel(), errors


def calibrate_intrinsics(
    images: Sequence[tuple[str, NDArray[np.generic]]],
    board: Board,
    fix_aspect: bool = False,
    max_view_error_px: float = 1.5,
) -> IntrinsicsResult:
    """Zhang calibration from named images (8-bit, 16-bit IR or RGB) of ``board``.

    Views whose reprojection error exceeds ``max_view_error_px`` are rejected with the reason
    and the solve is repeated without them. Raises FieldappError when too few views remain.
    """
    if not images:
        raise FieldappError("no images given")
    size = (int(images[0][1].shape[1]), int(images[0][1].shape[0]))
    views, corner_sets = [], []
    for name, image in images:
        if (image.shape[1], image.shape[0]) != size:
            raise FieldappError(
                f"{name}: size {image.shape[1]} x {image.shape[0]} differs "
                f"from the first image's {size[0]} x {size[1]}"
            )
        corners = detect_corners(image, board)
        views.append(
            ViewResult(
                name,
                corners is not None,
                rejected=None if corners is not None else "board not found",
            )
        )
        if corners is not None:
            corner_sets.append(corners)
    found = [v for v in views if v.found]
    if not found:
        raise FieldappError(
            f"no {board.cols} x {board.rows} board found in any image "
            f"({', '.join(v.name for v in views)}): check --board (inner corners, not squares); "
            "for IR images print the board on a laser printer: inkjet prints are often "
            "invisible in infrared"
        )
    if len(found) < MIN_VIEWS:
        raise FieldappError(
            f"the board was found in only {len(found)} image(s); at least "
            f"{MIN_VIEWS} are needed, {RECOMMENDED_VIEWS} or more recommended"
        )
    rms, K, dist, errors = _solve(corner_sets, board, size, fix_aspect)
    keep = [e <= max_view_error_px for e in errors]
    if not all(keep) and sum(keep) >= MIN_VIEWS:
        for view, error, kept in zip(found, errors, keep, strict=True):
            if not kept:
                view.rejected = (
                    f"reprojection error {error:.2f} px > {max_view_error_px} px "
                    "(blurred, board bent or moving, or corners misdetected)"
                )
        corner_sets = [c for c, k in zip(corner_sets, keep, strict=True) if k]
        rms, K, dist, errors = _solve(corner_sets, board, size, fix_aspect)
    for view, error in zip([v for v in found if v.rejected is None], errors, strict=True):
        view.error_px = error
    counts = coverage_of(corner_sets, size)
    result = IntrinsicsResult(
        Intrinsics(
            size[0],
            size[1],
            float(K[0, 0]),
            float(K[1, 1]),
            float(K[0, 2]),
            float(K[1, 2]),
            tuple(float(d) for d in dist[:5]),
        ),
        rms,
        views,
        float((counts > 0).mean()),
        counts,
    )
    result.warnings = intrinsics_warnings(result)
    return result


def intrinsics_warnings(result: IntrinsicsResult) -> list[str]:
    warnings = []
    used = len(result.used)
    if used < RECOMMENDED_VIEWS:
        warnings.append(
            f"only {used} good views: take at least {RECOMMENDED_VIEWS} for a "
            "calibration you can trust for a season"
        )
    missing = missing_regions(result.coverage_map)
    if missing:
        warnings.append(
            "no corners seen in the image's "
            + ", ".join(missing)
            + ": hold the board there too (distortion is fitted only where seen)"
        )
    return warnings
