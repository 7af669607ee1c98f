"""Applying ``corrections.json`` to a results folder: the plot's labelled cloud, corrected.

The automatic result is kept beside the corrected one (``plants.auto.csv``, ``leaves.auto.csv``,
``cloud.auto.ply`` with every point's plant, organ and leaf), and every application starts from
it and replays the operations in order, so the file is the whole history and undo is one
operation fewer. Only the point labels change on the way; at the end each plant an operation
touched is measured again with the reconstruction's own trait code (:mod:`fieldapp.recon.traits`
and the organ step), its organ traits blank when they cannot be measured, never stale. Then
``plants.csv``, ``leaves.csv``, ``cloud.ply`` and ``plants/`` are rewritten.

The ground under a plant is not in the folder (only the plants' points are). It is recovered
from the automatic result: each automatic plant's local ground is its highest point less its
``height_max_cm`` (or its robust top less its ``height_cm``), and these ground samples stand in
for the soil when a corrected plant is measured.

When a new reconstruction has overwritten the folder (``plants.csv`` or ``report.json`` no
longer what the last application wrote), its files become the automatic result and every
operation finds its plants again by position: the plant with the recorded id whose centroid is
within ``match_m`` of the recorded one, else the nearest plant within ``match_m``. An operation
whose plants are not found is reported in ``applied.unmatched`` and kept in the file.
"""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.io.durable import write_bytes_durably
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.outputs import LeafRow, PlantRow, PointLabels, read_results_cloud
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results import correction_ops
from fieldapp.results.correction_plot import PlotState, load_state, write_state
from fieldapp.results.corrections import Applied, Corrections, describe, save_corrections

AUTO_PLANTS = "plants.auto.csv"
AUTO_LEAVES = "leaves.auto.csv"
AUTO_CLOUD = "cloud.auto.ply"


class CorrectionError(FieldappError):
    """A correction that cannot be made (a stem picked off the plant, a number taken...)."""


@dataclass
class Result:
    """After an application: the corrections with ``applied`` filled in, the plants' rows and
    leaves as now written, and the problems of operations that could not be applied."""

    corrections: Corrections
    plants: list[PlantRow]
    leaves: list[LeafRow]
    problems: dict[int, str] = field(default_factory=dict)


def apply_corrections(
    folder: Path, corrections: Corrections, settings: ReconstructionSettings | None = None
) -> Result:
    """Apply ``corrections`` to the results ``folder`` (from its automatic result) and rewrite
    its files and ``corrections.json``."""
    settings = settings or ReconstructionSettings()
    snapshot_auto(folder, corrections)
    state = load_state(folder, settings)
    problems = correction_ops.replay(state, corrections.operations, settings)
    return _write(folder, state, corrections, problems)


def add_correction(
    folder: Path,
    corrections: Corrections,
    operation: correction_ops.AnyOperation,
    settings: ReconstructionSettings | None = None,
) -> Result:
    """Append ``operation`` and apply; raises :class:`CorrectionError` (writing nothing) when
    the new operation cannot be applied."""
    settings = settings or ReconstructionSettings()
    snapshot_auto(folder, corrections)
    state = load_state(folder, settings)
    added = corrections.adding(operation)
    problems = correction_ops.replay(state, added.operations, settings)
    last = len(added.operations) - 1
    if last in problems:
        raise CorrectionError(problems[last])
    return _write(folder, state, added, problems)


def undo_correction(
    folder: Path, corrections: Corrections, settings: ReconstructionSettings | None = None
) -> Result:
    """Drop the last operation and apply the others."""
    return apply_corrections(folder, corrections.undone(), settings)


def _write(
    folder: Path, state: PlotState, corrections: Corrections, problems: dict[int, str]
) -> Result:
    write_state(folder, state)
    unmatched = [
        f"operation {i + 1} ({describe(corrections.operations[i])}): {text}"
        for i, text in sorted(problems.items())
    ]
    applied = Applied(
        plants_csv_sha256=file_sha256(folder / "plants.csv"),
        report_sha256=file_sha256(folder / "report.json"),
        corrected=sorted(state.corrected & set(state.rows)),
        unmatched=unmatched,
    )
    done = corrections.model_copy(update={"applied": applied})
    save_corrections(folder, done)
    return Result(done, state.plant_rows(), state.leaf_rows(), problems)


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes; empty when it is missing."""
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else ""


def snapshot_auto(folder: Path, corrections: Corrections) -> bool:
    """Make sure ``folder``'s automatic result is kept in the ``*.auto.*`` files; True when
    they were taken now from the folder's files (a first correction or a new reconstruction),
    so operations must find their plants by position."""
    if snapshot_is_current(folder, corrections):
        return False
    cloud, labels = _labelled_cloud(folder)
    from fieldapp.recon.outputs import ply_bytes

    write_bytes_durably(folder / AUTO_CLOUD, ply_bytes(cloud, labels))
    shutil.copyfile(folder / "plants.csv", folder / AUTO_PLANTS)
    if (folder / "leaves.csv").is_file():
        shutil.copyfile(folder / "leaves.csv", folder / AUTO_LEAVES)
    else:
        (folder / AUTO_LEAVES).unlink(missing_ok=True)
    return True


def snapshot_is_current(folder: Path, corrections: Corrections) -> bool:
    """Whether ``folder`` holds what ``corrections`` were last applied to and wrote: its
    ``*.auto.*`` files are then the automatic result (no reconstruction has run since)."""
    applied = corrections.applied
    return (
        applied is not None
        and (folder / AUTO_PLANTS).is_file()
        and (folder / AUTO_CLOUD).is_file()
        and applied.plants_csv_sha256 == file_sha256(folder / "plants.csv")
        and applied.report_sha256 == file_sha256(folder / "report.json")
    )


def _labelled_cloud(folder: Path) -> tuple[Cloud, PointLabels]:
    """``cloud.ply`` with its per-point labels (:func:`read_results_cloud`)."""
    try:
        return read_results_cloud(folder)
    except FileNotFoundError:
        path = folder / "cloud.ply"
        message = f"{path}: missing: the results folder has no cloud to correct"
        raise CorrectionError(message) from None


def centroid_xy_m(points_m: NDArray[np.float64]) -> tuple[float, float]:
    """A plant's centroid in plan view (what corrections find plants again by)."""
    if len(points_m) == 0:
        raise ValueError("a plant without points has no centroid")
    x, y = points_m[:, :2].mean(axis=0)
    return float(x), float(y)
