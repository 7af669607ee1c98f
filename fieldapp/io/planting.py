"""The session's ``plan`` (session-format spec): the stations' map poses, views per station and
the planting grid, all in the base's map frame (metres, degrees).

Only what the reconstruction uses is modelled; the rest of a plan (a mission's devices,
retries...) is kept as written (``extra="allow"``).
"""

from __future__ import annotations

from pydantic import AliasChoices, Field, StrictInt

from fieldapp.io.calibration import FiniteFloat, SpecModel


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
    """A planned station and its map pose (``number``/``station``, ``x_m``/``x``, ``y_m``/``y``:
    the mission plan's names and the base pose's are both read)."""

    number: StrictInt = Field(ge=0, validation_alias=AliasChoices("number", "station"))
    x_m: FiniteFloat = Field(validation_alias=AliasChoices("x_m", "x"))
    y_m: FiniteFloat = Field(validation_alias=AliasChoices("y_m", "y"))
    yaw_deg: FiniteFloat = 0.0


class SessionPlan(SpecModel):
    """The plan a session was captured with, as far as reconstruction needs it."""

    stations: list[PlanStation] = Field(default_factory=list)
    planting_grid: PlantingGrid | None = None
