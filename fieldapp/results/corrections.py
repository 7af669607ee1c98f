"""Manual corrections of a reconstruction's plants: the ``corrections.json`` file.

An operator merges plants the reconstruction split, splits one it merged (by picking the stems),
deletes a phantom and renumbers a plant. Each correction is an :data:`Operation` appended to
the file, in order, with its time and author: the file is the history, and undo drops the last
operation and applies the rest again (:mod:`fieldapp.results.corrected` applies them).

Every plant an operation names is kept with the centroid (plan view, map/field frame) it had
when the operation was made, so a new reconstruction of the same session, which may number the
plants differently, finds the same plants again by position; ``applied`` records what the
folder's files hold after the last application.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Annotated, Final, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from fieldapp.io.durable import write_bytes_durably
from fieldapp.io.jsonfile import load_model

FORMAT: Final = "fieldapp-corrections/1"
FILE_NAME = "corrections.json"

XY = tuple[float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PlantRef(_Model):
    """A plant as the operation saw it: its id then and its centroid ``xy_m`` (plan view)."""

    plant: int = Field(ge=1)
    xy_m: XY


class _Operation(_Model):
    time: dt.datetime = Field(default_factory=lambda: dt.datetime.now(dt.UTC))
    author: str = ""


class Merge(_Operation):
    """``plants`` become one plant numbered ``into`` (one of theirs)."""

    kind: Literal["merge"] = "merge"
    plants: list[PlantRef] = Field(min_length=2)
    into: int = Field(ge=1)

    @model_validator(mode="after")
    def _into_is_merged(self) -> Merge:
        ids = [p.plant for p in self.plants]
        if len(set(ids)) != len(ids):
            raise ValueError("a plant is listed twice")
        if self.into not in ids:
            raise ValueError(f"into: {self.into} is not one of the merged plants {ids}")
        return self


class Split(_Operation):
    """``plant`` becomes one plant per stem foot of ``stems_xy_m`` (plan view), numbered
    ``into`` (the first keeps the plant's number)."""

    kind: Literal["split"] = "split"
    plant: PlantRef
    stems_xy_m: list[XY] = Field(min_length=2)
    into: list[Annotated[int, Field(ge=1)]]

    @model_validator(mode="after")
    def _one_number_per_stem(self) -> Split:
        if len(self.into) != len(self.stems_xy_m):
            raise ValueError(f"into: {len(self.into)} numbers for {len(self.stems_xy_m)} stems")
        if len(set(self.into)) != len(self.into) or self.into[0] != self.plant.plant:
            raise ValueError("into: distinct numbers, the first the split plant's own")
        return self


class Delete(_Operation):
    """``plant`` is no plant (a weed, a stone, a leaf seen twice): its points leave it."""

    kind: Literal["delete"] = "delete"
    plant: PlantRef


class Relabel(_Operation):
    """``plant`` is numbered ``into`` (a number no other plant has)."""

    kind: Literal["relabel"] = "relabel"
    plant: PlantRef
    into: int = Field(ge=1)


Operation = Annotated[Merge | Split | Delete | Relabel, Field(discriminator="kind")]


class Applied(_Model):
    """What the folder's files hold after the last application: the SHA-256 of ``plants.csv``
    and ``report.json`` then (a new reconstruction into the folder changes them), the plants
    corrected (recomputed or renumbered) and one line per operation that could not be applied."""

    plants_csv_sha256: str
    report_sha256: str
    corrected: list[int] = Field(default_factory=list)
    unmatched: list[str] = Field(default_factory=list)


class Corrections(_Model):
    """The ``corrections.json`` document."""

    format: Literal["fieldapp-corrections/1"] = FORMAT
    session: str = ""
    operations: list[Operation] = Field(default_factory=list)
    applied: Applied | None = None

    def undone(self) -> Corrections:
        """These corrections without the last operation."""
        if not self.operations:
            raise ValueError("nothing to undo")
        return self.model_copy(update={"operations": self.operations[:-1]})

    def adding(self, operation: Merge | Split | Delete | Relabel) -> Corrections:
        return self.model_copy(update={"operations": [*self.operations, operation]})


def load_corrections(path: Path) -> Corrections:
    """Read ``corrections.json``; a bad file raises :class:`~fieldapp.errors.FormatError`
    naming the file and each bad field (``operations[2].into``)."""
    return load_model(path, Corrections)


def read_corrections(folder: Path) -> Corrections | None:
    """The corrections of a results folder, ``None`` when it has none."""
    path = folder / FILE_NAME
    return load_corrections(path) if path.is_file() else None


def save_corrections(folder: Path, corrections: Corrections) -> None:
    """Write ``corrections.json`` into ``folder`` durably."""
    text = corrections.model_dump_json(indent=2) + "\n"
    write_bytes_durably(folder / FILE_NAME, text.encode("utf-8"))


def describe(operation: Merge | Split | Delete | Relabel) -> str:
    """One line for the operator: ``merge plants 3, 4 into 3``."""
    if isinstance(operation, Merge):
        ids = ", ".join(str(p.plant) for p in operation.plants)
        return f"merge plants {ids} into {operation.into}"
    if isinstance(operation, Split):
        return f"split plant {operation.plant.plant} into {', '.join(map(str, operation.into))}"
    if isinstance(operation, Delete):
        return f"delete plant {operation.plant.plant}"
    return f"renumber plant {operation.plant.plant} as {operation.into}"
