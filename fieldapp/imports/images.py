"""Reading the images of other tools: depth in any 16-bit or float form, colour, IR."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError


class Unusable(FieldappError):
    """An image that cannot be used, with the reason (the file is named)."""


def _load(path: Path) -> NDArray[Any]:
    if path.suffix.lower() == ".npy":
        try:
            return np.asarray(np.load(path, allow_pickle=False))
        except (OSError, ValueError) as error:
            raise Unusable(f"{path}: not a readable .npy array ({error})") from None
    data = path.read_bytes()
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if image is None:
        raise Unusable(f"{path}: not a decodable image (empty, truncated or corrupt?)")
    return np.asarray(image)


def read_depth_m(path: Path, depth_scale: float) -> NDArray[np.float32]:
    """(H, W) float32 metres, NaN where missing. 16-bit images are in 1/``depth_scale`` m;
    float images (``.npy``, 32-bit TIFF) are taken as metres."""
    image = _load(path)
    if image.ndim != 2:
        raise Unusable(f"{path}: not used as depth: {image.shape[2]} channels (depth has one)")
    if image.dtype == np.uint16:
        depth_m = image.astype(np.float32) / np.float32(depth_scale)
        depth_m[image == 0] = np.nan
        return depth_m
    if image.dtype in (np.float32, np.float64):
        depth_m = image.astype(np.float32)
        depth_m[~np.isfinite(depth_m) | (depth_m <= 0)] = np.nan
        return depth_m
    raise Unusable(
        f"{path}: not used as depth: {image.dtype} pixels (an 8-bit picture of depth, not "
        "measurements: export 16-bit PNG in millimetres, or float metres)"
    )


def read_color_rgb(path: Path) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB of an 8-bit colour image."""
    image = _load(path)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise Unusable(f"{path}: not used as colour: not an 8-bit RGB image")
    code = cv2.COLOR_BGR2RGB if image.shape[2] == 3 else cv2.COLOR_BGRA2RGB
    return np.ascontiguousarray(cv2.cvtColor(image, code))


def read_ir_u16(path: Path) -> NDArray[np.uint16]:
    """(H, W) uint16 IR; 8-bit IR is scaled by 257 to fill the 16-bit range."""
    image = _load(path)
    if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise Unusable(f"{path}: not used as IR: not a single-channel 8- or 16-bit image")
    if image.dtype == np.uint8:
        return image.astype(np.uint16) * np.uint16(257)
    return image
