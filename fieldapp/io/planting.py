"""The session's ``plan`` (session-format spec): the stations' map poses, views per station and
the planting grid, all in the base's map frame (metres, degrees).

Only what the reconstruction uses is modelled; the rest of a plan (a mission's devices,
retries...) is kept as written (``extra="allow"``).
"""

from __future__ import annotations

import logging
from typing import Any

from pydantic import (
    AliasChoices,
    Field,
    StrictInt,
    ValidationError,
    ValidatorFunctionWrapHandler,
    field_validator,
)

from fieldapp.io.calibration import FiniteFloat, SpecModel

log = logging.getLogger(__name__)


class MapPoint(SpecModel):
    """A point of the map frame (metres)."""

    x: FiniteFloat
    y: FiniteFloat


class PlantingGrid(SpecModel):
    """Where the plants were sown: ``rows`` x ``columns``, plants ``plant_spacing_m`` apart along
    a row (direction ``row_direction_deg`` from the map's x axis, counter-clockwise), rows
    ``row_spacing_m`` apart to the row's left; row 1, column 1 at ``origin``."""

    rows: StrictInt = Field(ge=1)
    columns: StrictInt = Field(ge=1)
    row_spacing_m: FiniteFloat = Field(gt=0)
    plant_spacing_m: FiniteFloat = Field(gt=0)
    origin: MapPoint
    row_direction_deg: FiniteFloat = 0.0

    @property
    def expected_plants(self) -> int:
        return self.rows * self.columns


class PlanStation(SpecModel):
    """A planned station and its map pose (``number``/``station``/``id``, ``x_m``/``x``,
    ``y_m``/``y``: the mission plan's names and the base pose's are read, also with the pose
    nested in ``map_pose`` or ``pose``)."""

    number: StrictInt = Field(ge=0, validation_alias=AliasChoices("number", "station", "id"))
    x_m: FiniteFloat = Field(validation_alias=AliasChoices("x_m", "x"))
    y_m: FiniteFloat = Field(validation_alias=AliasChoices("y_m", "y"))
    yaw_deg: FiniteFloat = 0.0


class SessionPlan(SpecModel):
    """The plan a session was captured with, as far as reconstruction needs it."""

    stations: list[PlanStation] = Field(default_factory=list)
    planting_grid: PlantingGrid | None = None

    @field_validator("stations", mode="wrap")
    @classmethod
    def _stations_as_far_as_readable(
        cls, value: Any, handler: ValidatorFunctionWrapHandler
    ) -> list[PlanStation]:
        """The spec names no fields for the plan's stations: the common shapes are read (a
        list of stations, or an object keyed by station number; the pose flat or nested), and
        a plan in another shape is left out with a warning: a session is never refused for
        what only informs its reconstruction (the captures' base poses then place it)."""
        try:
            stations: list[PlanStation] = handler(_station_entries(value))
        except ValidationError as error:
            first = error.errors()[0]
            where = ".".join(str(part) for part in first["loc"])
            log.warning(
                "session.json: plan.stations not read (%s%s: %s): the plan's station poses "
                "are left out",
                "stations" + ("." if where else ""),
                where,
                first["msg"],
            )
            return []
        return stations


def _station_entries(value: Any) -> Any:
    """``plan.stations`` as a list of flat entries, where it has one of the common shapes."""
    if isinstance(value, dict):  # {"1": {...}, "2": {...}}
        value = [
            {"number": int(key), **entry}
            if isinstance(entry, dict) and str(key).isdigit()
            else entry
            for key, entry in value.items()
        ]
    if not isinstance(value, list):
        return value
    flat = []
    for entry in value:
        if isinstance(entry, dict):
            nested = next(
                (entry[k] for k in ("map_pose", "pose") if isinstance(entry.get(k), dict)), None
            )
            if nested is not None:
                entry = {
                    **{k: v for k, v in entry.items() if k not in ("map_pose", "pose")},
                    **nested,
                }
        flat.append(entry)
    return flat
