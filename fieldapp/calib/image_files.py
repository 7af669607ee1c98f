"""The images of a calibration: files, folders and glob patterns, unreadable ones skipped."""

from __future__ import annotations

import glob
import re
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm"}
_GLOB = re.compile(r"[*?\[]")


def _natural(path: Path) -> list[object]:
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", str(path))]


def expand_image_paths(arguments: Sequence[Path]) -> list[Path]:
    """Each argument as files: a file itself, a folder's image files (not recursive), a glob
    pattern's matches; in natural order, each once. Raises when an argument gives nothing."""
    found: list[Path] = []
    for argument in arguments:
        text = str(argument)
        if argument.is_dir():
            matches = [p for p in argument.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES]
            if not matches:
                kinds = ", ".join(sorted(IMAGE_SUFFIXES))
                raise FieldappError(f"{argument}: a folder with no image files ({kinds})")
        elif _GLOB.search(text) and not argument.exists():
            matches = [Path(p) for p in glob.glob(text) if Path(p).is_file()]
            if not matches:
                raise FieldappError(f"{argument}: the pattern matches no file")
        elif argument.is_file():
            matches = [argument]
        else:
            raise FieldappError(
                f"{argument}: no such file or folder (give image files, a folder of them, or a "
                "quoted pattern such as 'ir/*.png')"
            )
        found += sorted(matches, key=_natural)
    return list(dict.fromkeys(found))


def read_images(paths: Sequence[Path]) -> tuple[list[tuple[str, NDArray[np.generic]]], list[str]]:
    """(name, image) of every readable file, and a warning for each one skipped."""
    images, skipped = [], []
    for path in paths:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.stat().st_size else None
        if image is None:
            why = "empty file" if path.stat().st_size == 0 else "not a readable image"
            skipped.append(f"{path}: skipped: {why}")
        else:
            images.append((str(path), np.asarray(image)))
    if not images:
        raise FieldappError("no readable image among:\n  " + "\n  ".join(skipped))
    return images, skipped
