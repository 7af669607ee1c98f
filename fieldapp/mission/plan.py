"""The mission plan: data (pydantic), saved as YAML or JSON and into every session folder.

A plan lists the stations in visiting order with their map poses (the base's navigation frame:
metres, degrees), the views of each station (``count`` views ``step_deg`` apart), how many
frames make one capture, the settle time after each table move, the capture quality limits,
bounded retries, the devices, the calibration in force and, when known, the planting grid (map
frame, written into the session's ``plan``). :func:`default_plan` is the paper's:
a 3 x 3 grid 1.6 m apart, reference station 5 at its centre, visited in serpentine order, with
8 views 45 degrees apart at each station.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import Field, field_validator, model_validator

from fieldapp.errors import FormatError, Problem
from fieldapp.io.durable import write_bytes_durably
from fieldapp.io.jsonfile import validate_document
from fieldapp.io.planting import PlantingGrid
from fieldapp.settings import CameraQualitySettings, DeviceSettings, IncidentPolicy, Section

PLAN_FORMAT: Literal["fieldapp-mission/1"] = "fieldapp-mission/1"
GRID_SPACING_M = 1.6
REFERENCE_STATION = 5


class StationPlan(Section):
    """One station: its number (as the calibration names it) and its map pose."""

    number: int = Field(ge=1)
    x_m: float = Field(allow_inf_nan=False)
    y_m: float = Field(allow_inf_nan=False)
    yaw_deg: float = Field(default=0.0, allow_inf_nan=False)


class ViewPlan(Section):
    """Views 0..count-1 at table angles ``view * step_deg``."""

    count: int = Field(default=8, ge=1, le=360)
    step_deg: float = Field(default=45.0, gt=0, le=360)
    alternate: bool = True
    """Turn back through the views at every other station (no rewind of the table)."""

    @model_validator(mode="after")
    def _one_turn_at_most(self) -> ViewPlan:
        if (self.count - 1) * self.step_deg >= 360.0:
            raise ValueError(f"{self.count} views {self.step_deg:g} deg apart overlap a turn")
        return self

    def angle_deg(self, view: int) -> float:
        return view * self.step_deg


class RetryLimits(Section):
    """How many times a failed step is tried again before the mission stops."""

    navigation: int = Field(default=2, ge=0, le=10)
    """Goals the base gave up on (aborted), or a base link that dropped."""
    table: int = Field(default=1, ge=0, le=5)
    """Table moves that ended off target."""
    camera: int = Field(default=2, ge=0, le=10)
    """Captures that timed out."""
    quality: int = Field(default=2, ge=0, le=10)
    """Captures below the quality limits."""
    base_link_wait_s: float = Field(default=2.0, ge=0, le=60)
    """How long to wait for a lost base link before trying again."""


class SimulationPlan(Section):
    """The simulated world, when a device is simulated."""

    seed: int = Field(default=0, ge=0)
    day: int = Field(default=0, ge=0, le=120)


class MissionPlan(Section):
    """Everything a mission needs to run, and nothing that changes while it runs."""

    format: Literal["fieldapp-mission/1"] = PLAN_FORMAT
    name: str = Field(default="plot", min_length=1)
    stations: list[StationPlan] = Field(min_length=1)
    reference_station: int = REFERENCE_STATION
    views: ViewPlan = Field(default_factory=ViewPlan)
    frames_per_capture: int = Field(default=5, ge=1, le=100)
    settle_s: float = Field(default=0.5, ge=0, le=60)
    frame_timeout_s: float = Field(default=2.0, gt=0, le=60)
    navigation_timeout_s: float = Field(default=300.0, gt=0)
    quality: CameraQualitySettings = Field(default_factory=CameraQualitySettings)
    keep_low_quality: bool = False
    """Keep a view still below the quality limits after its retries (with a warning) instead
    of stopping the mission."""
    retries: RetryLimits = Field(default_factory=RetryLimits)
    incidents: IncidentPolicy = Field(default_factory=IncidentPolicy)
    devices: DeviceSettings = Field(default_factory=DeviceSettings)
    calibration: Path | None = None
    """The calibration file in force; ``None`` with a simulated camera: the simulated rig's
    nominal calibration."""
    simulation: SimulationPlan = Field(default_factory=SimulationPlan)
    planting_grid: PlantingGrid | None = None
    """Where the plants were sown (map frame), when known: the reconstruction's stem prior,
    and the row and column of each plant in ``plants.csv``."""

    @field_validator("stations")
    @classmethod
    def _unique_stations(cls, stations: list[StationPlan]) -> list[StationPlan]:
        numbers = [s.number for s in stations]
        repeated = sorted({n for n in numbers if numbers.count(n) > 1})
        if repeated:
            raise ValueError(f"station numbers repeat: {repeated}")
        return stations

    @model_validator(mode="after")
    def _reference_planned(self) -> MissionPlan:
        if self.reference_station not in self.station_numbers():
            raise ValueError(f"reference station {self.reference_station} is not in the plan")
        return self

    def station_numbers(self) -> list[int]:
        """Station numbers in visiting order."""
        return [s.number for s in self.stations]

    def station(self, number: int) -> StationPlan:
        return next(s for s in self.stations if s.number == number)

    def session_plan(self) -> dict[str, Any]:
        """The session's ``plan`` (session-format spec): stations with their map poses, views
        per station and the planting grid when known."""
        document: dict[str, Any] = {
            "stations": [s.model_dump(mode="json") for s in self.stations],
            "views": self.views.model_dump(mode="json"),
        }
        if self.planting_grid is not None:
            document["planting_grid"] = self.planting_grid.model_dump(mode="json")
        return document

    def capture_keys(self) -> list[tuple[int, int]]:
        """Every (station, view) the mission captures, in plan order."""
        return [(s, v) for s in self.station_numbers() for v in range(self.views.count)]


def grid_stations(
    rows: int = 3, cols: int = 3, spacing_m: float = GRID_SPACING_M
) -> list[StationPlan]:
    """A rows x cols grid numbered row by row from 1 at the map origin (rows along +y), in
    serpentine visiting order: 1 2 3, 6 5 4, 7 8 9."""
    stations = []
    for row in range(rows):
        cols_order = range(cols) if row % 2 == 0 else reversed(range(cols))
        for col in cols_order:
            stations.append(
                StationPlan(number=row * cols + col + 1, x_m=col * spacing_m, y_m=row * spacing_m)
            )
    return stations


def default_plan(devices: DeviceSettings | None = None) -> MissionPlan:
    """The paper's plan: 3 x 3 stations 1.6 m apart, reference 5, 8 views of 45 degrees."""
    return MissionPlan(stations=grid_stations(), devices=devices or DeviceSettings())


def plan_text(plan: MissionPlan, path: Path) -> str:
    """The plan as YAML (or JSON when ``path`` ends in ``.json``)."""
    document = plan.model_dump(mode="json")
    if path.suffix.lower() == ".json":
        import json

        return json.dumps(document, indent=2) + "\n"
    return yaml.safe_dump(document, sort_keys=False)


def save_plan(plan: MissionPlan, path: Path) -> Path:
    """Write ``plan`` durably as YAML or JSON (by the file's extension)."""
    write_bytes_durably(path, plan_text(plan, path).encode("utf-8"))
    return path


def load_plan(path: Path) -> MissionPlan:
    """Read a YAML or JSON plan; raises :class:`FormatError` naming the file and each bad field."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FormatError([Problem(str(path), "", "plan file is missing")]) from None
    except (OSError, UnicodeDecodeError) as error:
        raise FormatError([Problem(str(path), "", f"cannot read the plan: {error}")]) from None
    try:
        document = yaml.safe_load(text)  # JSON is YAML too
    except yaml.YAMLError as error:
        raise FormatError([Problem(str(path), "", f"malformed YAML/JSON: {error}")]) from None
    if not isinstance(document, dict):
        raise FormatError([Problem(str(path), "", "a plan must be a mapping of fields")])
    _reject_non_finite(path, document)
    return validate_document(path, document, MissionPlan)


def _reject_non_finite(path: Path, document: object, where: str = "") -> None:
    """YAML reads ``.nan``/``.inf``; a plan never has them."""
    if isinstance(document, float) and not math.isfinite(document):
        raise FormatError([Problem(str(path), where or "(document)", "not a finite number")])
    if isinstance(document, dict):
        for key, value in document.items():
            _reject_non_finite(path, value, f"{where}.{key}" if where else str(key))
    elif isinstance(document, list):
        for index, value in enumerate(document):
            _reject_non_finite(path, value, f"{where}[{index}]")
