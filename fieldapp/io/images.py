"""Depth, colour and IR images as the spec stores them (16-bit PNG depth, 8-bit RGB colour)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import Problem

MAX_DEPTH_UNITS = 65535


class ImageError(Exception):
    """An image file is missing, undecodable or of the wrong kind; carries a :class:`Problem`."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        super().__init__(str(problem))


def _decode(path: Path, field: str) -> NDArray[Any]:
    """The image as stored (``IMREAD_UNCHANGED``)."""
    import cv2  # here, not at the top: importing OpenCV costs the GUI's start-up

    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ImageError(Problem(str(path), field, "file is missing")) from None
    except OSError as error:
        raise ImageError(Problem(str(path), field, f"cannot read: {error.strerror}")) from None
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if image is None:
        raise ImageError(Problem(str(path), field, "not a decodable image (truncated or corrupt?)"))
    return np.asarray(image)


def read_depth_units(path: Path, field: str = "depth") -> NDArray[np.uint16]:
    """Read a depth PNG as stored: (H, W) uint16 in 1/depth_scale metres, 0 = no measurement."""
    image = _decode(path, field)
    if image.ndim != 2:
        raise ImageError(
            Problem(
                str(path), field, f"depth must be single-channel, got {image.shape[2]} channels"
            )
        )
    if image.dtype != np.uint16:
        raise ImageError(Problem(str(path), field, f"depth must be 16-bit, got {image.dtype}"))
    return image


def read_color(path: Path, field: str = "color") -> NDArray[np.uint8]:
    """Read a colour image (PNG or JPEG) as (H, W, 3) uint8 RGB."""
    import cv2

    image = _decode(path, field)
    if image.dtype != np.uint8:
        raise ImageError(Problem(str(path), field, f"colour must be 8-bit, got {image.dtype}"))
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ImageError(Problem(str(path), field, "colour must be an RGB image"))
    code = cv2.COLOR_BGR2RGB if image.shape[2] == 3 else cv2.COLOR_BGRA2RGB
    return np.ascontiguousarray(cv2.cvtColor(image, code))


def read_ir(path: Path, field: str = "ir") -> NDArray[np.uint16]:
    """Read an IR PNG: (H, W) uint16."""
    image = _decode(path, field)
    if image.ndim != 2 or image.dtype != np.uint16:
        raise ImageError(Problem(str(path), field, "IR must be a single-channel 16-bit PNG"))
    return image


def depth_m_to_units(depth_m: NDArray[np.floating], depth_scale: float) -> NDArray[np.uint16]:
    """Metres (NaN or <= 0 for missing) to stored units, rounded; beyond range is missing."""
    units = np.rint(np.nan_to_num(depth_m, nan=0.0) * depth_scale)
    units[(units < 0) | (units > MAX_DEPTH_UNITS)] = 0
    return units.astype(np.uint16)  # type: ignore[no-any-return]


def depth_units_to_m(units: NDArray[np.uint16], depth_scale: float) -> NDArray[np.float32]:
    """Stored units to metres as float32, NaN where there is no measurement."""
    depth_m = units.astype(np.float32) / np.float32(depth_scale)
    depth_m[units == 0] = np.nan
    return depth_m


def encode_png(image: NDArray[Any], rgb: bool = False) -> bytes:
    """PNG bytes of a (H, W) uint16/uint8 image, or of an (H, W, 3) RGB image when ``rgb``."""
    import cv2

    if rgb:
        image = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR)
    ok, buffer = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise ValueError("PNG encoding failed")
    return buffer.tobytes()
