"""The work of one Dask task: reconstruct one session and write its outputs.

:func:`reconstruct_session` runs on a worker. It takes plain data (the session folder, the
settings as a JSON-ready mapping, the batch's output folder) and returns a small
:class:`SessionSummary`, so nothing big travels back to the client. It never touches the
results database: the client records the run when the summary arrives.

Failures of the data (a bad session, nothing to reconstruct, an unwritable output folder) come
back as a summary with ``ok=False`` and the message; they are not retried. Anything else is
raised, so that Dask retries the task (``retries=`` on submit) and then reports it.
"""

from __future__ import annotations

import logging
import os
import socket
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldapp import __version__
from fieldapp.errors import FieldappError

log = logging.getLogger(__name__)


class BatchError(FieldappError):
    """A batch cannot run as asked (bad option, unreachable scheduler, unsafe session id)."""


@dataclass(frozen=True)
class SessionSummary:
    """What a worker reports about one session.

    ``results_dir``: where the outputs went (``""`` on failure); ``wall_s``/``cpu_s``: the
    task's own time on the worker; ``worker``: ``host:pid`` of the process that ran it.
    """

    session_dir: str
    session_id: str
    ok: bool
    message: str
    plants: int
    warnings: int
    results_dir: str
    wall_s: float
    cpu_s: float
    worker: str
    software_version: str


def results_folder(out_dir: Path, session_id: str) -> Path:
    """``out_dir/<session id>``; raises :class:`BatchError` when the id is not a safe single
    folder name (empty, ``.``/``..``, a separator or a control character)."""
    unsafe = (
        session_id in {"", ".", ".."}
        or any(sep in session_id for sep in ("/", "\\"))
        or any(ord(c) < 32 for c in session_id)
    )
    if unsafe:
        raise BatchError(f"session id {session_id!r} cannot name a results folder")
    return out_dir / session_id


def reconstruct_session(
    session_dir: str, settings: Mapping[str, Any], out_dir: str
) -> SessionSummary:
    """Reconstruct the session in ``session_dir`` with ``settings`` (a dumped
    :class:`~fieldapp.recon.settings.ReconstructionSettings`) and write its outputs under
    ``out_dir/<session id>/``. Top-level and picklable: this is what a Dask task runs."""
    from fieldapp.io.session import load_session
    from fieldapp.provenance import provenance_of
    from fieldapp.recon.outputs import write_outputs
    from fieldapp.recon.pipeline import run_reconstruction
    from fieldapp.recon.settings import ReconstructionSettings

    started_s, started_cpu_s = time.perf_counter(), time.process_time()
    summary = _Timer(session_dir, started_s, started_cpu_s)
    session_id = ""
    try:
        parsed = ReconstructionSettings.model_validate(dict(settings))
        session = load_session(Path(session_dir))
        session_id = session.id
        folder = results_folder(Path(out_dir), session_id)
        result = run_reconstruction(session, parsed)
        plant_clouds = {p.id: p.cloud for p in result.plants}
        write_outputs(
            folder,
            result.rows(),
            result.cloud,
            plant_clouds,
            result.report(),
            **result.output_extras(),
            provenance=provenance_of(session, parsed),
        )
    except (FieldappError, OSError, ValueError) as error:
        log.warning("%s: %s", session_dir, error)
        return summary.failed(session_id, f"{type(error).__name__}: {error}")
    return summary.done(session_id, len(result.plants), len(result.warnings), folder)


@dataclass(frozen=True)
class _Timer:
    session_dir: str
    started_s: float
    started_cpu_s: float

    def _summary(self, **fields: Any) -> SessionSummary:
        return SessionSummary(
            session_dir=self.session_dir,
            wall_s=time.perf_counter() - self.started_s,
            cpu_s=time.process_time() - self.started_cpu_s,
            worker=f"{socket.gethostname()}:{os.getpid()}",
            software_version=__version__,
            **fields,
        )

    def failed(self, session_id: str, message: str) -> SessionSummary:
        return self._summary(
            session_id=session_id, ok=False, message=message, plants=0, warnings=0, results_dir=""
        )

    def done(self, session_id: str, plants: int, warnings: int, folder: Path) -> SessionSummary:
        return self._summary(
            session_id=session_id,
            ok=True,
            message="",
            plants=plants,
            warnings=warnings,
            results_dir=str(folder),
        )
