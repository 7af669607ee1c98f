"""The desktop entry (``desktop-file-validate`` and its keys) and the icon files."""

from __future__ import annotations

import configparser
import shutil
import struct
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

PACKAGING = Path(__file__).resolve().parents[2] / "packaging"
DESKTOP = PACKAGING / "fieldapp.desktop"
ICONS = PACKAGING / "icons"

needs_validator = pytest.mark.skipif(
    shutil.which("desktop-file-validate") is None,
    reason="desktop-file-validate missing (apt-get install desktop-file-utils)",
)


def desktop_entry(path: Path) -> dict[str, str]:
    parser = configparser.ConfigParser(interpolation=None, strict=True)
    parser.optionxform = str  # type: ignore[assignment,method-assign]  # keys are case-sensitive
    parser.read_string(path.read_text(encoding="utf-8"))
    return dict(parser["Desktop Entry"])


def validate(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["desktop-file-validate", str(path)], capture_output=True, text=True, timeout=30
    )


@needs_validator
def test_desktop_file_validate_accepts_the_entry() -> None:
    done = validate(DESKTOP)
    assert done.returncode == 0 and not done.stdout.strip(), done.stdout + done.stderr


@needs_validator
def test_the_validator_can_fail(tmp_path: Path) -> None:
    broken = tmp_path / "broken.desktop"
    broken.write_text(DESKTOP.read_text(encoding="utf-8").replace("Type=Application\n", ""))
    assert validate(broken).returncode != 0


def test_entry_opens_the_gui_with_the_fieldapp_icon() -> None:
    entry = desktop_entry(DESKTOP)
    assert entry["Type"] == "Application"
    assert entry["Exec"] == "fieldapp gui"  # install.sh makes the path absolute
    assert entry["TryExec"] == "fieldapp"
    assert entry["Icon"] == "fieldapp"  # a theme name: installed under hicolor
    assert entry["Terminal"] == "false"
    assert "Science" in entry["Categories"].split(";")


def test_icon_svg_is_a_square_drawing() -> None:
    root = ET.parse(ICONS / "fieldapp.svg").getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    x, y, width, height = (float(v) for v in root.attrib["viewBox"].split())
    assert (x, y) == (0.0, 0.0) and width == height > 0
    assert len(list(root.iter("{http://www.w3.org/2000/svg}path"))) >= 3


def png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    width, height = struct.unpack(">II", header[16:24])
    return width, height


@pytest.mark.parametrize("size", [48, 128, 256])
def test_png_icons_have_the_size_of_their_folder(size: int) -> None:
    path = ICONS / "hicolor" / f"{size}x{size}" / "apps" / "fieldapp.png"
    assert png_size(path) == (size, size)
