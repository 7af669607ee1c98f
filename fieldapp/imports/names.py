"""What an image file's name says: its kind (depth, colour, IR) and its station, view or angle.

Names are split into tokens at ``_ - . space`` and folder separators. A token ``depth``,
``color``/``colour``/``rgb`` or ``ir``/``infrared`` gives the kind (a parent folder named so
counts too); ``s3``/``station3``, ``v2``/``view2`` and ``45deg``/``angle45``/``a45`` give the
station, view and table angle. Files whose names differ only by their kind token are one capture.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".npy"}
KINDS = {
    "depth": "depth",
    "color": "color",
    "colour": "color",
    "rgb": "color",
    "ir": "ir",
    "infrared": "ir",
}
_SPLIT = re.compile(r"[_\-.\s/\\]+")
_STATION = re.compile(r"^(?:s|st|station)(\d+)$")
_VIEW = re.compile(r"^(?:v|view)(\d+)$")
_ANGLE = re.compile(r"^(?:(?:a|angle)(\d+(?:p\d+)?)(?:deg)?|(\d+(?:p\d+)?)deg)$")


@dataclass(frozen=True)
class NamedFile:
    """One image file and what its name says."""

    path: Path
    kind: str | None
    key: str
    """The name without its kind token and suffix: files of one capture share it."""
    station: int | None
    view: int | None
    angle_deg: float | None


def tokens(relative: str) -> list[str]:
    return [t for t in _SPLIT.split(relative.lower()) if t]


def parse_name(path: Path, folder: Path) -> NamedFile:
    """What ``path`` (inside ``folder``) says about itself."""
    relative = path.relative_to(folder).with_suffix("").as_posix()
    parts = tokens(relative)
    kind = next((KINDS[t] for t in parts if t in KINDS), None)
    rest = [t for t in parts if t not in KINDS]
    station = view = None
    angle = None
    for token in rest:
        if match := _STATION.match(token):
            station = int(match[1])
        elif match := _VIEW.match(token):
            view = int(match[1])
        elif match := _ANGLE.match(token):
            angle = float((match[1] or match[2]).replace("p", "."))
    return NamedFile(path, kind, "/".join(rest), station, view, angle)


def natural_key(text: str) -> list[object]:
    """Sort key putting ``frame2`` before ``frame10``."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def image_files(folder: Path) -> list[Path]:
    """Every image file under ``folder`` (recursively), in natural order."""
    found = [p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(found, key=lambda p: natural_key(p.relative_to(folder).as_posix()))
