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
SATURATION_LEVEL = 0.98
"""Pixels at or above this fraction of the image's full scale count as saturated."""
WASHED_OUT_CORNERS = 0.0
"""A rejected view with more of its corners washed out than this (any) is named over-exposed. A
corner is washed out when most (``WASHED_OUT_PIXELS``) of the pixels around it are saturated:
its dark squares are clipped too (clipped white squares alone, half the pixels at most, are
common and harmless)."""
WASHED_OUT_PIXELS = 0.6
SATURATED_IMAGE = 0.05
"""An image where the board is not found and more of the pixels than this are saturated is
named possibly over-exposed."""


@dataclass(frozen=True)
class SolveOptions:
    """What the Zhang solve keeps fixed. ``principal_point``: fix cx, cy (at ``(cx, cy)`` when
    given, else at the image centre); ``fix_k3``: k3 = 0 (few views let k1, k2, k3 trade off)."""

    fix_aspect: bool = False
    fix_principal_point: bool = False
    principal_point: tuple[float, float] | None = None
    fix_k3: bool = False


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


def _saturated(image: NDArray[np.generic]) -> NDArray[np.bool_]:
    full = 255.0 if image.dtype == np.uint8 else float(np.iinfo(np.uint16).max)
    gray = image.min(axis=2) if image.ndim == 3 else image
    return np.asarray(gray, np.float64) >= SATURATION_LEVEL * full


def saturated_fraction(image: NDArray[np.generic]) -> float:
    """Fraction of the image's pixels that are saturated."""
    return float(_saturated(image).mean())


def washed_out_fraction(
    image: NDArray[np.generic], corners: NDArray[np.float32], board: Board
) -> float:
    """Fraction of the corners (N, 2) with most pixels within half a square saturated."""
    saturated = _saturated(image).astype(np.float32)
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    side = 2 * max(1, round(spacing / 2)) + 1
    share = cv2.blur(saturated, (side, side))
    x = np.clip(np.round(corners[:, 0]).astype(int), 0, saturated.shape[1] - 1)
    y = np.clip(np.round(corners[:, 1]).astype(int), 0, saturated.shape[0] - 1)
    return float((share[y, x] > WASHED_OUT_PIXELS).mean())


OVER_EXPOSURE_ADVICE = (
    "move the board out of direct light or lower the exposure; for IR, away from the "
    "emitter's hot spot"
)


def _solve(
    corner_sets: list[NDArray[np.float32]],
    board: Board,
    size: tuple[int, int],
    options: SolveOptions,
) -> tuple[float, NDArray[np.float64], NDArray[np.float64], list[float]]:
    objects = [board.object_points_m().astype(np.float32)] * len(corner_sets)
    images = [c.reshape(-1, 1, 2) for c in corner_sets]
    flags, K0 = _flags_and_guess(objects, images, size, options)
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(objects, images, size, K0, None, flags=flags)
    errors = []
    for obj, img, r, t in zip(objects, images, rvecs, tvecs, strict=True):
        projected, _ = cv2.projectPoints(obj, r, t, K, dist)
        errors.append(float(np.sqrt(np.mean(np.sum((projected - img) ** 2, axis=2)))))
    return float(rms), K, dist.ravel(), errors


def _flags_and_guess(
    objects: list[NDArray[np.float32]],
    images: list[NDArray[np.float32]],
    size: tuple[int, int],
    options: SolveOptions,
) -> tuple[int, NDArray[np.float64]]:
    flags = cv2.CALIB_FIX_ASPECT_RATIO if options.fix_aspect else 0
    flags |= cv2.CALIB_FIX_K3 if options.fix_k3 else 0
    K0 = np.eye(3)
    if options.fix_principal_point:
        flags |= cv2.CALIB_FIX_PRINCIPAL_POINT
        if options.principal_point is not None:
            K0 = np.asarray(cv2.initCameraMatrix2D(objects, images, size), np.float64)
            K0[0, 2], K0[1, 2] = options.principal_point
            flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    return flags, K0


def calibrate_intrinsics(
    images: Sequence[tuple[str, NDArray[np.generic]]],
    board: Board,
    fix_aspect: bool = False,
    max_view_error_px: float = 1.5,
    options: SolveOptions | None = None,
) -> IntrinsicsResult:
    """Zhang calibration from named images (8-bit, 16-bit IR or RGB) of ``board``.

    Views whose reprojection error exceeds ``max_view_error_px`` are rejected with the reason
    (over-exposure named when the board's pixels are saturated) and the solve is repeated
    without them. ``options`` fixes the principal point or k3 (``fix_aspect`` is kept for
    callers that only set that). Raises FieldappError when too few views remain.
    """
    options = options or SolveOptions(fix_aspect=fix_aspect)
    if not images:
        raise FieldappError("no images given")
    size = _common_size(images)
    views, corner_sets, saturation = [], [], []
    for name, image in images:
        if (image.shape[1], image.shape[0]) != size:
            views.append(
                ViewResult(
                    name,
                    False,
                    rejected=f"size {image.shape[1]} x {image.shape[0]} differs from the "
                    f"other images' {size[0]} x {size[1]} (another camera?)",
                )
            )
            continue
        corners = detect_corners(image, board)
        views.append(ViewResult(name, corners is not None, rejected=_not_found(image, corners)))
        if corners is not None:
            corner_sets.append(corners)
            saturation.append(washed_out_fraction(image, corners, board))
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
    rms, K, dist, errors = _solve(corner_sets, board, size, options)
    keep = [e <= max_view_error_px for e in errors]
    if not all(keep) and sum(keep) >= MIN_VIEWS:
        for view, error, kept, saturated in zip(found, errors, keep, saturation, strict=True):
            if not kept:
                view.rejected = _rejection(error, max_view_error_px, saturated)
        corner_sets = [c for c, k in zip(corner_sets, keep, strict=True) if k]
        rms, K, dist, errors = _solve(corner_sets, board, size, options)
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


def _common_size(images: Sequence[tuple[str, NDArray[np.generic]]]) -> tuple[int, int]:
    """(width, height) most of the images have (the first such on a tie)."""
    sizes = [(int(image.shape[1]), int(image.shape[0])) for _, image in images]
    return max(dict.fromkeys(sizes), key=sizes.count)


def _not_found(image: NDArray[np.generic], corners: NDArray[np.float32] | None) -> str | None:
    if corners is not None:
        return None
    fraction = saturated_fraction(image)
    if fraction > SATURATED_IMAGE:
        return (
            f"board not found; {100 * fraction:.0f} % of the image is saturated: over-exposed? "
            f"({OVER_EXPOSURE_ADVICE})"
        )
    return "board not found"


def _rejection(error_px: float, max_error_px: float, washed_out: float) -> str:
    reason = f"reprojection error {error_px:.2f} px > {max_error_px} px"
    if washed_out > WASHED_OUT_CORNERS:
        return (
            f"{reason}: over-exposed: {100 * washed_out:.0f} % of the corners sit on a saturated "
            f"patch ({OVER_EXPOSURE_ADVICE})"
        )
    return f"{reason} (blurred, board bent or moving, or corners misdetected)"


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
