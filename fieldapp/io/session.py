"""Capture sessions (``fieldapp-session/1``): models, loading, reading captures, durable writing."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path, PurePosixPath
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import AfterValidator, Field, StrictInt

from fieldapp.errors import FormatError, Problem
from fieldapp.io.calibration import Calibration, FiniteFloat, SpecModel, load_calibration
from fieldapp.io.files import resolves_inside
from fieldapp.io.images import (
    Expected,
    ImageError,
    read_color,
    read_depth_units,
    read_ir,
)
from fieldapp.io.jsonfile import load_model
from fieldapp.io.planting import SessionPlan
from fieldapp.io.plausible import MIN_VIEW_STEP_DEG, calibration_problems

SESSION_FORMAT = "fieldapp-session/1"
SESSION_FILE = "session.json"


_DRIVE = re.compile(r"[A-Za-z]:")
"""A Windows drive (``C:``, ``C:frames``): absolute, or relative to another folder. A colon
elsewhere is a name's (``2026-12-06T02:22:04/``)."""


def _relative_path(value: str) -> str:
    path = PurePosixPath(value.replace("\\", "/"))
    if not value.strip():
        raise ValueError("path is empty")
    if any(ord(c) < 32 for c in value):
        raise ValueError(f"path {value!r} has control characters")
    if path.is_absolute() or value.startswith(("/", "\\")) or _DRIVE.match(path.parts[0]):
        raise ValueError(f"path {value!r} must be relative to the session folder")
    if ".." in path.parts:
        raise ValueError(f"path {value!r} escapes the session folder")
    return value


RelativePath = Annotated[str, AfterValidator(_relative_path)]
"""A path inside the session folder, forward slashes, never absolute or with ``..``."""

Sha256Hex = Annotated[str, Field(pattern=r"^[0-9a-fA-F]{64}$")]
"""A SHA-256 digest as 64 hex digits."""

FILE_FIELDS = ("depth", "color", "ir")


class BasePose(SpecModel):
    """The base's pose as it reported it (map frame, metres, degrees)."""

    x: FiniteFloat
    y: FiniteFloat
    yaw_deg: FiniteFloat


class Capture(SpecModel):
    """One capture: a depth image of view ``view`` at station ``station``, and a colour image
    registered to it unless the capture is depth-only.

    ``sha256`` names the SHA-256 of each file (``{"depth": hex, "color": hex}``) when the
    writer recorded them. Extra fields are kept, e.g. ``target`` (the calibration board a
    capture sees).
    """

    station: StrictInt = Field(ge=0)
    view: StrictInt = Field(ge=0)
    depth: RelativePath
    color: RelativePath | None = None
    angle_deg: FiniteFloat | None = None
    captured_at: datetime | None = None
    base_pose: BasePose | None = None
    ir: RelativePath | None = None
    sha256: dict[str, Sha256Hex] | None = None

    def checksum(self, name: str) -> str | None:
        """The recorded SHA-256 of file ``name`` ("depth", "color", "ir"), if any."""
        return (self.sha256 or {}).get(name)

    def files(self) -> dict[str, str]:
        """The capture's files by field name ("depth", "color", "ir"), relative paths."""
        named = {name: getattr(self, name) for name in FILE_FIELDS}
        return {name: path for name, path in named.items() if path}

    @property
    def key(self) -> tuple[int, int, str | None]:
        """(station, view, target): what must be unique in a session."""
        target = getattr(self, "target", None)
        return self.station, self.view, target if isinstance(target, str) else None


class Turntable(SpecModel):
    """What the turntable carries (this project's field addition to the spec): ``camera``
    (the rig of the paper: the camera turns, the scene stands still) or ``plant`` (a lab rig:
    the camera is fixed and the plant turns on the table). ``working_radius_m``: how far from
    the table's axis the plant may reach; everything farther is the room and is masked."""

    carries: Literal["camera", "plant"] = "camera"
    working_radius_m: FiniteFloat | None = Field(default=None, gt=0)


class SessionDocument(SpecModel):
    """The ``session.json`` document."""

    format: Literal["fieldapp-session/1"]
    id: str | None = Field(default=None, min_length=1)
    """Optional here: the spec lists no top-level field as required, and another recorder's
    session without one is read under its folder's name (:attr:`Session.id`)."""
    created: datetime | None = None
    calibration: RelativePath
    captures: list[Capture]
    turntable: Turntable | None = None
    plan: SessionPlan | None = None


@dataclass
class CaptureImages:
    """A capture's images, decoded.

    - ``depth_m``: (H, W) float32 metres along the optical axis, NaN where missing.
    - ``color``: (H, W, 3) uint8 RGB, registered to depth.
    - ``ir``: (H, W) uint16 or ``None``.
    """

    capture: Capture
    depth_m: NDArray[np.float32]
    color: NDArray[np.uint8]
    ir: NDArray[np.uint16] | None = None


@dataclass
class Session:
    """A loaded session folder: its document and the calibration it names."""

    folder: Path
    document: SessionDocument
    calibration: Calibration

    @property
    def id(self) -> str:
        """The document's ``id``, or the folder's name where it has none."""
        return self.document.id or self.folder.resolve().name

    @property
    def captures(self) -> list[Capture]:
        return self.document.captures

    def path_of(self, relative: str) -> Path:
        return self.folder / relative

    def expected(self, capture: Capture, name: str) -> Expected:
        """What file ``name`` of ``capture`` must be: the calibration's size, its checksum."""
        camera = self.calibration.depth_camera
        hw_from = "the calibration's" if name == "depth" else "the depth camera's (calibration)"
        return Expected((camera.height, camera.width), hw_from, capture.checksum(name))

    def read_capture(self, capture: Capture, with_ir: bool = False) -> CaptureImages:
        """Decode one capture's images, each checked for size and checksum before decoding;
        raises :class:`FormatError` naming the bad file."""
        camera = self.calibration.depth_camera
        if capture.color is None:
            raise FormatError([depth_only_problem(self, capture)])
        try:
            units = read_depth_units(
                self.path_of(capture.depth), expected=self.expected(capture, "depth")
            )
            color = read_color(
                self.path_of(capture.color), expected=self.expected(capture, "color")
            )
            ir = None
            if with_ir and capture.ir:
                ir = read_ir(self.path_of(capture.ir), expected=self.expected(capture, "ir"))
        except ImageError as error:
            raise FormatError([error.problem]) from None
        return CaptureImages(capture, camera.metres(units), color, ir)

    def iter_captures(self, with_ir: bool = False) -> Iterator[CaptureImages]:
        """Yield every capture's images in session order."""
        for capture in self.captures:
            yield self.read_capture(capture, with_ir=with_ir)

    def stations(self) -> list[int]:
        return sorted({c.station for c in self.captures})

    def expected_keys(self) -> set[tuple[int, int]]:
        """(station, view) pairs a complete session has: calibrated stations x views per turn."""
        stations = set(self.stations())
        if self.calibration.stations is not None:
            stations |= set(self.calibration.stations.to_reference)
        views = self.calibration.view_step.views_per_turn if self.calibration.view_step else 1
        return {(s, v) for s in stations for v in range(views)}

    def missing(self) -> list[tuple[int, int]]:
        """(station, view) pairs with no capture, sorted."""
        present = {(c.station, c.view) for c in self.captures}
        return sorted(self.expected_keys() - present)


def depth_only_problem(session: Session, capture: Capture) -> Problem:
    """What a colour reader says of a depth-only capture (valid in the format, but the
    colour-based steps cannot use it)."""
    return Problem(
        str(session.path_of(capture.depth)),
        "color",
        f"station {capture.station} view {capture.view} is depth-only (no colour image): "
        "this step needs colour",
    )


def structure_problems(folder: Path, document: SessionDocument) -> list[Problem]:
    """What is wrong with a valid document as a whole: paths escaping the folder through
    links, checksums of files the capture lacks, duplicates."""
    session_file = str(folder / SESSION_FILE)
    problems = []
    root = folder.resolve()
    if resolves_inside(folder / document.calibration, root) is False:
        problems.append(Problem(session_file, "calibration", "path escapes the folder"))
    seen: dict[tuple[int, int, str | None], int] = {}
    for index, capture in enumerate(document.captures):
        files = capture.files()
        for name, relative in files.items():
            if resolves_inside(folder / relative, root) is False:
                problems.append(
                    Problem(session_file, f"captures[{index}].{name}", "path escapes the folder")
                )
        for name in sorted(set(capture.sha256 or {}) & set(FILE_FIELDS) - set(files)):
            problems.append(
                Problem(session_file, f"captures[{index}].sha256.{name}", "names no file")
            )
        if capture.key in seen:
            problems.append(
                Problem(
                    session_file,
                    f"captures[{index}]",
                    f"station {capture.station} view {capture.view} is already captured "
                    f"by captures[{seen[capture.key]}]",
                )
            )
        seen.setdefault(capture.key, index)
    return problems


def load_session(folder: Path, allow_empty: bool = False) -> Session:
    """Load and check a session folder's documents (not its images: see :func:`verify`).

    Raises :class:`FormatError` listing every problem found.
    """
    if not folder.is_dir():
        raise FormatError([Problem(str(folder), "", "not a session folder (no such folder)")])
    document = load_model(folder / SESSION_FILE, SessionDocument)
    problems = structure_problems(folder, document)
    if not document.captures and not allow_empty:
        problems.append(Problem(str(folder / SESSION_FILE), "captures", "session has no captures"))
    calibration: Calibration | None = None
    try:
        calibration = load_calibration(folder / document.calibration)
        problems += session_calibration_problems(folder / document.calibration, calibration)
        problems += view_problems(folder, document, calibration)
    except FormatError as error:
        problems += error.problems
    if problems or calibration is None:
        raise FormatError(problems)
    return Session(folder, document, calibration)


def view_problems(
    folder: Path, document: SessionDocument, calibration: Calibration
) -> list[Problem]:
    """Every capture's view must be one of a turn's (view k: the table at k x the step)."""
    if calibration.view_step is None or abs(calibration.view_step.angle_deg) < MIN_VIEW_STEP_DEG:
        return []
    views = calibration.view_step.views_per_turn
    return [
        Problem(
            str(folder / SESSION_FILE),
            f"captures[{index}].view",
            f"view {capture.view} is beyond the {views} views of a turn "
            f"(view_step.angle_deg {calibration.view_step.angle_deg:g})",
        )
        for index, capture in enumerate(document.captures)
        if capture.view >= views
    ]


def session_calibration_problems(path: Path, calibration: Calibration) -> list[Problem]:
    """A session's calibration must be physically possible and say how views and stations
    join."""
    problems = calibration_problems(path, calibration)
    if calibration.view_step is None:
        problems.append(Problem(str(path), "view_step", "missing (needed to join the views)"))
    if calibration.stations is None:
        problems.append(Problem(str(path), "stations", "missing (needed to join the stations)"))
    return problems


def document_of(session: Session) -> dict[str, Any]:
    """The session document as JSON-ready data."""
    return session.document.model_dump(mode="json", exclude_none=True)


def now_iso() -> str:
    """The current local time with its UTC offset, ISO 8601, seconds."""
    return datetime.now().astimezone().isoformat(timespec="seconds")


def reported_base_poses(session: Session) -> dict[int, tuple[float, float, float]]:
    """Per station, the mean of the map poses (x_m, y_m, yaw_deg) the base reported at its
    captures (the yaw's mean on the circle)."""
    reported: dict[int, list[tuple[float, float, float]]] = {}
    for capture in session.captures:
        pose = capture.base_pose
        if pose is not None:
            reported.setdefault(capture.station, []).append((pose.x, pose.y, pose.yaw_deg))
    poses: dict[int, tuple[float, float, float]] = {}
    for station, values in reported.items():
        array = np.asarray(values, dtype=np.float64)
        yaw = np.radians(array[:, 2])
        mean_yaw = float(np.degrees(np.arctan2(np.sin(yaw).mean(), np.cos(yaw).mean())))
        poses[station] = (float(array[:, 0].mean()), float(array[:, 1].mean()), mean_yaw)
    return poses
