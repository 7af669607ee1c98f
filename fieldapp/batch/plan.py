"""What a batch will do, decided on the client before anything is submitted.

Each session folder is read (its documents, not its images) to learn its id and plot; folders
that cannot be read, ids that cannot name a results folder and ids seen twice are failures up
front; sessions the results database already holds a complete run of, with the same settings
hash and software version, are skipped.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fieldapp.batch.task import results_folder
from fieldapp.errors import FieldappError
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.db import ResultsDB
from fieldapp.results.sources import settings_hash

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BatchItem:
    """A session to reconstruct: its folder (absolute), id and the plot it is recorded under."""

    session_dir: Path
    session_id: str
    plot: str


@dataclass(frozen=True)
class Rejected:
    """A session folder the batch cannot run, and why."""

    session_dir: Path
    message: str


@dataclass
class BatchPlan:
    """``to_run`` in the given order; ``skipped``: already done; ``rejected``: unusable."""

    settings: dict[str, Any]
    settings_sha256: str
    software_version: str
    to_run: list[BatchItem] = field(default_factory=list)
    skipped: list[BatchItem] = field(default_factory=list)
    rejected: list[Rejected] = field(default_factory=list)


def task_settings(settings: ReconstructionSettings, threads: int = 1) -> dict[str, Any]:
    """The settings a task runs with, as JSON-ready data: ``settings`` with ``threads``
    reconstruction threads (one per worker thread by default). Their hash is the one the
    results database keeps, so a re-run with the same settings finds its runs."""
    return settings.model_copy(update={"threads": threads}).model_dump(mode="json")


def session_plot(session_dir: Path, plot: str | None) -> tuple[str, str]:
    """(session id, plot) of a session folder: the plot is ``plot`` when given, else the
    session document's ``plot`` field, else the session id. Raises ``FieldappError``."""
    from fieldapp.io.session import load_session

    session = load_session(session_dir)
    extra = session.document.model_extra or {}
    own_plot = extra.get("plot")
    if plot is None and isinstance(own_plot, str) and own_plot.strip():
        plot = own_plot
    return session.id, plot or session.id


def plan_batch(
    session_dirs: Sequence[Path],
    settings: Mapping[str, Any],
    software_version: str,
    db: ResultsDB,
    out_dir: Path,
    plot: str | None = None,
) -> BatchPlan:
    """Sort ``session_dirs`` into sessions to run, to skip and that cannot run."""
    plan = BatchPlan(dict(settings), settings_hash(settings), software_version)
    seen: dict[str, Path] = {}
    for given in session_dirs:
        folder = Path(given).resolve()
        try:
            session_id, session_plot_name = session_plot(folder, plot)
            results_folder(out_dir, session_id)
        except FieldappError as error:
            plan.rejected.append(Rejected(folder, str(error)))
            continue
        if session_id in seen:
            message = f"session id {session_id!r} is also the id of {seen[session_id]}"
            plan.rejected.append(Rejected(folder, message))
            continue
        seen[session_id] = folder
        item = BatchItem(folder, session_id, session_plot_name)
        if db.is_done(session_id, plan.settings_sha256, software_version):
            plan.skipped.append(item)
        else:
            plan.to_run.append(item)
    log.info(
        "batch: %d to run, %d already done, %d unusable",
        len(plan.to_run),
        len(plan.skipped),
        len(plan.rejected),
    )
    return plan
