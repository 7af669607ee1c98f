"""Depth, colour and IR images as the spec stores them (16-bit PNG depth, 8-bit RGB colour)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import Problem
from fieldapp.io.files import UnreadableFile, read_regular_file
from fieldapp.io.headers import HeaderError, ImageHeader, read_header

MAX_DEPTH_UNITS = 65535
MAX_IMAGE_SIDE = 16384
"""No side longer than this (pixels): 8 x a 1920-pixel colour camera's."""
MAX_IMAGE_PIXELS = 4096 * 4096
"""No image larger than this (16.8 Mpx; a Kinect v2 depth image has 0.22 Mpx): a colour image
of this size decodes into 50 MB, a depth image into 34 MB."""
MAX_IMAGE_BYTES = 128 * 1024 * 1024
"""No image file larger than this: a PNG of the largest allowed size, uncompressed, and more."""


class ImageError(Exception):
    """An image file is missing, undecodable or of the wrong kind; carries a :class:`Problem`."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        super().__init__(str(problem))


@dataclass(frozen=True)
class Expected:
    """What a caller knows before reading: the size ``(H, W)`` (and whose size it is: "the
    calibration's", "the depth image's") and the SHA-256 the session recorded."""

    hw: tuple[int, int] | None = None
    hw_from: str = "the calibration's"
    sha256: str | None = None


NOTHING_EXPECTED = Expected()


def _header(path: Path, field: str, expected: Expected) -> tuple[bytes, ImageHeader]:
    """The file's bytes and header, checked (regular file, checksum, size) before decoding."""

    def problem(message: str) -> ImageError:
        return ImageError(Problem(str(path), field, message))

    try:
        data = read_regular_file(path, MAX_IMAGE_BYTES, "an image")
    except UnreadableFile as error:
        raise problem(str(error)) from None
    if expected.sha256 is not None and sha256_hex(data) != expected.sha256.lower():
        raise problem("damaged: its SHA-256 differs from the one session.json records")
    try:
        header = read_header(data)
    except HeaderError as error:
        raise problem(f"not a decodable image ({error})") from None
    if max(header.width, header.height) > MAX_IMAGE_SIDE or header.pixels > MAX_IMAGE_PIXELS:
        raise problem(
            f"header claims {header.width} x {header.height} pixels, more than an image "
            f"may have ({MAX_IMAGE_PIXELS} pixels, sides up to {MAX_IMAGE_SIDE})"
        )
    if expected.hw is not None and (header.height, header.width) != tuple(expected.hw):
        height, width = expected.hw
        raise problem(
            f"size {header.width} x {header.height} differs from {expected.hw_from} "
            f"{width} x {height}"
        )
    return data, header


def _decode(path: Path, field: str, data: bytes, header: ImageHeader) -> NDArray[Any]:
    import cv2  # here, not at the top: importing OpenCV costs the GUI's start-up

    try:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        image = None
    if image is None:
        raise ImageError(Problem(str(path), field, "not a decodable image (truncated or corrupt?)"))
    if image.shape[:2] != (header.height, header.width):
        raise ImageError(Problem(str(path), field, "decoded size differs from its header"))
    return np.asarray(image)


def read_depth_units(
    path: Path, field: str = "depth", expected: Expected = NOTHING_EXPECTED
) -> NDArray[np.uint16]:
    """Read a depth PNG as stored: (H, W) uint16 in 1/depth_scale metres, 0 = no measurement."""
    data, header = _header(path, field, expected)
    if header.format != "png":
        raise ImageError(Problem(str(path), field, "depth must be a PNG image"))
    if header.channels != 1:
        raise ImageError(
            Problem(str(path), field, f"depth must be single-channel, got {header.channels}")
        )
    if header.bit_depth != 16:
        raise ImageError(
            Problem(str(path), field, f"depth must be 16-bit, got {header.bit_depth}-bit")
        )
    image = _decode(path, field, data, header)
    if image.ndim != 2 or image.dtype != np.uint16:
        raise ImageError(Problem(str(path), field, "depth must be a single-channel 16-bit PNG"))
    return image


def read_color(
    path: Path, field: str = "color", expected: Expected = NOTHING_EXPECTED
) -> NDArray[np.uint8]:
    """Read a colour image (PNG or JPEG) as (H, W, 3) uint8 RGB."""
    data, header = _header(path, field, expected)
    if header.bit_depth != 8:
        raise ImageError(
            Problem(str(path), field, f"colour must be 8-bit, got {header.bit_depth}-bit")
        )
    if header.channels not in (3, 4):
        raise ImageError(Problem(str(path), field, "colour must be an RGB image"))
    image = _decode(path, field, data, header)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ImageError(Problem(str(path), field, "colour must be an 8-bit RGB image"))
    import cv2

    code = cv2.COLOR_BGR2RGB if image.shape[2] == 3 else cv2.COLOR_BGRA2RGB
    return np.ascontiguousarray(cv2.cvtColor(image, code))


def read_ir(
    path: Path, field: str = "ir", expected: Expected = NOTHING_EXPECTED
) -> NDArray[np.uint16]:
    """Read an IR PNG: (H, W) uint16."""
    data, header = _header(path, field, expected)
    if header.format != "png" or header.channels != 1 or header.bit_depth != 16:
        raise ImageError(Problem(str(path), field, "IR must be a single-channel 16-bit PNG"))
    image = _decode(path, field, data, header)
    if image.ndim != 2 or image.dtype != np.uint16:
        raise ImageError(Problem(str(path), field, "IR must be a single-channel 16-bit PNG"))
    return image


def sha256_hex(data: bytes) -> str:
    """The SHA-256 of ``data`` as 64 lowercase hex digits (the session format's checksum)."""
    return hashlib.sha256(data).hexdigest()


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
