"""Fuzz: a seeded corpus of damaged sessions through ``verify`` and ``reconstruct``.

Each case copies the small simulated session, damages it one way (session.json,
calibration.json, an image's bytes or pixels, or the file system: FIFOs, links, folders), then
runs ``fieldapp verify`` and the reconstruction in-process. Every case must end in a result or
in the project's typed errors with one-line messages: zero tracebacks. A hang fails the test
through the suite's per-test timeout, so each family of cases is bounded.

``FIELDAPP_FUZZ_SEED`` (default 0) and ``FIELDAPP_FUZZ_CASES`` (per family, default 40) run
other or more cases by hand.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import random
import shutil
import struct
import traceback
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.io.session import load_session
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import ReconstructionSettings

BASE_SEED = int(os.environ.get("FIELDAPP_FUZZ_SEED", "0"))
CASES = int(os.environ.get("FIELDAPP_FUZZ_CASES", "40"))

ODD_VALUES: list[Any] = [
    None,
    True,
    -1,
    0,
    1,
    2**63,
    1e308,
    -1e308,
    1e-308,
    4.5,
    "",
    "x" * 300,
    "NaN",
    [],
    {},
    [[1, 2], [3]],
    {"a": {"b": [None]}},
    "../../etc/passwd",
    "/dev/zero",
    "frames",
    "calibration.json",
    "frames/s05/v0/color.png",
    "frames/s04/v1/ir.png",
    "session.json",
]
FACTORS = [0.0, -1.0, 1e-300, 1e-3, 0.5, 0.99, 1.01, 2.0, 10.0, 1e3, 1e300]


# ---- mutations of the JSON documents -----------------------------------------------------


def _slots(document: Any) -> list[tuple[Any, Any]]:
    """Every (container, key or index) of a JSON document."""
    found: list[tuple[Any, Any]] = []
    items = document.items() if isinstance(document, dict) else enumerate(document)
    for key, value in items:
        found.append((document, key))
        if isinstance(value, dict | list) and value:
            found += _slots(value)
    return found


def _replace_any(rng: random.Random, document: Any) -> None:
    container, key = rng.choice(_slots(document))
    value = container[key]
    if isinstance(value, int | float) and not isinstance(value, bool) and rng.random() < 0.6:
        container[key] = value * rng.choice(FACTORS)
    else:
        container[key] = rng.choice(ODD_VALUES)


def _delete_any(rng: random.Random, document: Any) -> None:
    container, key = rng.choice(_slots(document))
    del container[key]


def _captures(rng: random.Random, document: Any) -> None:
    captures = document["captures"]
    how = rng.randrange(5)
    if how == 0:
        captures.append(dict(rng.choice(captures)))
    elif how == 1:
        capture = rng.choice(captures)
        capture["depth"], capture["color"] = capture["color"], capture["depth"]
    elif how == 2:
        rng.choice(captures)["station"] = rng.choice([0, 99, 10**9, 2**62])
    elif how == 3:
        rng.choice(captures)["view"] = rng.choice([7, 8, 360, 10**12])
    else:
        document["captures"] = rng.sample(captures, rng.randrange(len(captures) + 1))


def _camera(rng: random.Random, document: Any) -> None:
    camera = document["depth_camera"]
    field = rng.choice(["width", "height", "fx", "fy", "cx", "cy", "depth_scale", "distortion"])
    if field == "distortion":
        length = rng.choice([0, 3, 4, 5, 8, 12, 14])
        scale = rng.choice([1e-3, 0.1, 0.5, 1.0, 100.0, 1e300])
        camera[field] = [rng.gauss(0.0, scale) for _ in range(length)]
    elif field in ("width", "height") and rng.random() < 0.7:
        camera[field] = max(1, int(camera[field] * rng.choice([0.5, 0.99, 1.01, 2.0, 1000.0])))
    else:
        camera[field] = camera[field] * rng.choice(FACTORS)


def _matrices(rng: random.Random, document: Any) -> None:
    candidates = [document["view_step"]["matrix"], document["ground"]["matrix"]]
    candidates += list(document["stations"]["to_reference"].values())
    matrix = rng.choice(candidates)
    how = rng.randrange(4)
    if how == 0:  # a valid rotation about z and any translation
        angle = rng.uniform(-np.pi, np.pi)
        c, s = np.cos(angle), np.sin(angle)
        matrix[0][:2], matrix[1][:2] = [c, -s], [s, c]
        matrix[rng.randrange(3)][3] = rng.choice([-1, 1]) * 10 ** rng.uniform(-3, 12)
    elif how == 1:
        matrix[rng.randrange(4)][rng.randrange(4)] *= rng.choice(FACTORS)
    elif how == 2:
        document["view_step"]["angle_deg"] = rng.choice([0, -45, 1e-9, 7.0, 180, 360, 1e6])
    else:
        stations = document["stations"]
        stations["reference"] = rng.choice([0, 1, 4, 99])
        if rng.random() < 0.5:
            stations["to_reference"].pop(rng.choice(list(stations["to_reference"])))


JsonMutation = Callable[[random.Random, Any], None]
SESSION_MUTATIONS: list[JsonMutation] = [_replace_any, _delete_any, _captures]
CALIBRATION_MUTATIONS: list[JsonMutation] = [_replace_any, _delete_any, _camera, _matrices]


def _mutate_json(rng: random.Random, path: Path, mutations: list[JsonMutation]) -> str:
    raw = path.read_bytes()
    how = rng.randrange(10)
    if how == 0:
        path.write_bytes(raw[: rng.randrange(len(raw))])
        return "truncated"
    if how == 1:
        path.write_bytes(_flip_bytes(rng, raw, rng.randint(1, 8)))
        return "bytes flipped"
    document = json.loads(raw)
    mutation = rng.choice(mutations)
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        try:
            mutation(rng, document)
        except (KeyError, IndexError, TypeError, AttributeError):
            break  # an earlier mutation removed what this one changes
    path.write_text(json.dumps(document))
    return mutation.__name__.strip("_")


# ---- mutations of images -------------------------------------------------------------------


def _flip_bytes(rng: random.Random, data: bytes, count: int, start: int = 0) -> bytes:
    buffer = bytearray(data)
    for _ in range(count):
        buffer[rng.randrange(min(start, len(buffer) - 1), len(buffer))] = rng.randrange(256)
    return bytes(buffer)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


@functools.cache
def _text_bomb() -> bytes:
    """A PNG zTXt chunk of 64 KB that inflates to 64 MB."""
    return _png_chunk(b"zTXt", b"k\0\0" + zlib.compress(b"\0" * (64 << 20), 9))


def _header_size(rng: random.Random, data: bytes, fix_crc: bool) -> bytes:
    """The PNG header's width and height rewritten (mostly claims of huge images)."""
    width = rng.choice([0, 1, 257, 100_000, 1_000_000, 2**31 - 1, 2**32 - 1])
    height = rng.choice([0, 212, 100_000, 2**31 - 1])
    ihdr = bytearray(data[8:33])
    ihdr[8:16] = struct.pack(">II", width, height)
    if fix_crc:
        ihdr[21:25] = struct.pack(">I", zlib.crc32(bytes(ihdr[4:21])) & 0xFFFFFFFF)
    return data[:8] + bytes(ihdr) + data[33:]


def _image_bytes(rng: random.Random, path: Path) -> str:
    data = path.read_bytes()
    how = rng.randrange(9)
    if how == 0:
        data = data[: rng.randrange(len(data))]
    elif how == 1:
        data = _flip_bytes(rng, data, rng.randint(1, 4), start=0)
    elif how == 2:
        data = _flip_bytes(rng, data, rng.randint(1, 64), start=33)
    elif how in (3, 4, 5):
        data = _header_size(rng, data, fix_crc=how != 5)
    elif how == 6:  # a compressed text chunk that inflates to 64 MB
        data = data[:33] + _text_bomb() + data[33:]
    elif how == 7:
        data = b""
    else:
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 2000)))
    path.write_bytes(data)
    return f"bytes ({how})"


def _image_pixels(rng: random.Random, path: Path) -> str:
    h, w = 212, 256
    how = rng.randrange(7)
    images: list[np.ndarray] = [
        np.zeros((h, w), np.uint16),
        np.full((h, w), 65535, np.uint16),
        np.random.default_rng(rng.randrange(2**32)).integers(0, 65536, (h, w), dtype=np.uint16),
        np.zeros((h, w), np.uint8),
        np.full((h, w, 3), (0, 200, 0), np.uint8),
        np.zeros((h, w, 3), np.uint16),
        np.zeros((h * 2, w // 2), np.uint16),
    ]
    extension = rng.choice([".png", ".png", ".jpg", ".tiff", ".bmp"])
    image = images[how]
    if extension == ".jpg" and image.dtype != np.uint8:
        image = (image >> 8).astype(np.uint8)
    ok, encoded = cv2.imencode(extension, image)
    assert ok
    path.write_bytes(encoded.tobytes())
    return f"pixels ({how}, {extension})"


def _image_swap(rng: random.Random, path: Path) -> str:
    others = [p for p in path.parent.parent.parent.rglob("*.png") if p != path]
    shutil.copyfile(rng.choice(others), path)
    return "swapped with another file"


# ---- mutations of the file system ------------------------------------------------------------


def _filesystem(rng: random.Random, path: Path, folder: Path) -> str:
    how = rng.randrange(7)
    path.unlink()
    if how == 0:
        os.mkfifo(path)
    elif how == 1:
        path.mkdir()
    elif how == 2:
        path.symlink_to(path.name)
    elif how == 3:
        path.symlink_to("missing.png")
    elif how == 4:
        path.symlink_to("/dev/zero")
    elif how == 5:
        outside = folder.parent / "outside.png"
        outside.write_bytes(b"\x89PNG\r\n\x1a\n")
        path.symlink_to(outside)
    else:
        others = [p for p in folder.rglob("*.png") if p != path]
        path.symlink_to(os.path.relpath(rng.choice(others), path.parent))
    return ["fifo", "folder", "link loop", "dangling link", "/dev/zero", "outside", "inside"][how]


# ---- one case ----------------------------------------------------------------------------------


def _refresh_checksums(folder: Path) -> None:
    """Record the files' current SHA-256, as a writer would have (so the damage is decoded)."""
    path = folder / "session.json"
    document = json.loads(path.read_text())
    for capture in document["captures"]:
        for name in list(capture.get("sha256", {})):
            file = folder / capture[name]
            if file.is_file() and not file.is_symlink():
                capture["sha256"][name] = hashlib.sha256(file.read_bytes()).hexdigest()
    path.write_text(json.dumps(document))


def _damage(family: str, rng: random.Random, folder: Path) -> str:
    images = sorted(folder.rglob("*.png"))
    if family == "session":
        return _mutate_json(rng, folder / "session.json", SESSION_MUTATIONS)
    if family == "calibration":
        return _mutate_json(rng, folder / "calibration.json", CALIBRATION_MUTATIONS)
    if family == "image":
        target = rng.choice(images)
        what = rng.choice([_image_bytes, _image_bytes, _image_pixels, _image_swap])(rng, target)
        if rng.random() < 0.7:
            _refresh_checksums(folder)
        return f"{target.relative_to(folder)}: {what}"
    target = rng.choice([*images, folder / "session.json", folder / "calibration.json"])
    return f"{target.relative_to(folder)}: {_filesystem(rng, target, folder)}"


def _run_case(folder: Path, capsys: pytest.CaptureFixture[str]) -> list[str]:
    """What went wrong (tracebacks, multi-line or empty messages), nothing when all is well."""
    findings = []
    try:
        code = main(["verify", str(folder)])
        out, err = capsys.readouterr()
        problems = [line for line in err.splitlines() if line.startswith("problem: ")]
        if code not in (0, 1) or (code == 1 and not problems) or "Traceback" in out + err:
            findings.append(f"verify: exit {code}, {err!r}")
    except Exception:  # a finding, reported with its traceback
        findings.append(f"verify raised:\n{traceback.format_exc()}")
    try:
        result = run_reconstruction(load_session(folder), ReconstructionSettings())
        findings += [f"multi-line warning: {w!r}" for w in result.warnings if "\n" in w]
    except FieldappError as error:
        problems = getattr(error, "problems", None) or [error]
        if not str(error).strip() or any("\n" in str(p) for p in problems):
            findings.append(f"reconstruct: unclear error {error!r}")
    except Exception:  # a finding, reported with its traceback
        findings.append(f"reconstruct raised:\n{traceback.format_exc()}")
    return findings


@pytest.mark.parametrize("family", ["session", "calibration", "image", "filesystem"])
def test_damaged_sessions_never_crash_or_hang(small_session, tmp_path, capsys, family):
    logging.disable(logging.WARNING)  # the reconstruction's warnings, 40 times over
    try:
        findings: list[str] = []
        kinds: set[str] = set()
        for index in range(CASES):
            rng = random.Random(f"{BASE_SEED}-{family}-{index}")
            folder = tmp_path / f"case{index}"
            shutil.copytree(small_session, folder, symlinks=True)
            what = _damage(family, rng, folder)
            kinds.add(what.split(" (")[0])
            findings += [f"case {index} ({what}): {f}" for f in _run_case(folder, capsys)]
            shutil.rmtree(folder)
    finally:
        logging.disable(logging.NOTSET)
    assert not findings, "\n\n".join(findings)
    assert len(kinds) >= 3  # the corpus really varies
