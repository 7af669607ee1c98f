"""The reconstruction in a child process, behind the same generator interface.

Open3D and small_gicp do much of their work holding the interpreter, so a reconstruction on a
thread makes a GUI stall for hundreds of milliseconds; in its own process it cannot, and a crash
in native code cannot take the caller down either. :func:`reconstruct_in_process` yields the
child's :class:`Progress` events; closing it cancels the child at its next step boundary. The
child writes the outputs (``fieldapp reconstruct``'s files) itself; the caller reads them back.
"""

from __future__ import annotations

import logging
import multiprocessing
from collections.abc import Generator
from multiprocessing.connection import Connection
from multiprocessing.synchronize import Event
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError
from fieldapp.io.session import load_session
from fieldapp.recon.early import start_reading
from fieldapp.recon.progress import Progress
from fieldapp.recon.settings import ReconstructionSettings

log = logging.getLogger(__name__)

POLL_S = 0.1
STOP_WAIT_S = 15.0


def reconstruct_in_process(
    session_folder: Path, settings: ReconstructionSettings, results_dir: Path
) -> Generator[Progress, None, dict[str, Any]]:
    """Reconstruct ``session_folder`` into ``results_dir`` in a child process.

    Yields progress; returns ``{"plants": n, "warnings": [...]}``. Raises
    :class:`FieldappError` with the child's message when it fails or dies.
    """
    context = multiprocessing.get_context("spawn")  # never fork a process that runs Qt threads
    receiver, sender = context.Pipe(duplex=False)
    cancel = context.Event()
    child = context.Process(
        target=_child,
        args=(str(session_folder), settings.model_dump_json(), str(results_dir), sender, cancel),
        name="fieldapp-reconstruct",
        daemon=True,
    )
    child.start()
    sender.close()
    finished = False
    try:
        while True:
            kind, payload = _receive(receiver, child)
            if kind == "progress":
                yield payload
            elif kind == "done":
                finished = True
                return dict(payload)
            else:
                raise FieldappError(str(payload))
    finally:
        if not finished:
            cancel.set()
        child.join(STOP_WAIT_S)
        if child.is_alive():
            log.warning("the reconstruction process did not stop in time: terminating it")
            child.terminate()
            child.join(STOP_WAIT_S)
        receiver.close()
        child.close()


def _receive(receiver: Connection, child: Any) -> tuple[str, Any]:
    while not receiver.poll(POLL_S):
        if not child.is_alive() and not receiver.poll(0):
            raise FieldappError(
                f"the reconstruction process ended unexpectedly (exit code {child.exitcode})"
            )
    try:
        message: tuple[str, Any] = receiver.recv()
    except EOFError:
        raise FieldappError("the reconstruction process ended without a result") from None
    return message


def _child(
    session_folder: str, settings_json: str, results_dir: str, sender: Connection, cancel: Event
) -> None:
    """The child's side: run the pipeline, send progress, write the outputs. As in ``fieldapp
    reconstruct``, a reader forked before the pipeline's modules are imported (this process is
    spawned fresh: SciPy, small_gicp) starts on the stations while they load."""
    early = None
    try:
        settings = ReconstructionSettings.model_validate_json(settings_json)
        session = load_session(Path(session_folder))
        early = start_reading(session, settings)
        from fieldapp.provenance import provenance_of
        from fieldapp.recon.outputs import write_outputs
        from fieldapp.recon.pipeline import reconstruct

        steps = reconstruct(session, settings, early)
        while True:
            if cancel.is_set():
                steps.close()
                return
            try:
                sender.send(("progress", next(steps)))
            except StopIteration as done:
                result = done.value
                break
        plant_clouds = {plant.id: plant.cloud for plant in result.plants}
        write_outputs(
            Path(results_dir),
            result.rows(),
            result.cloud,
            plant_clouds,
            result.report(),
            **result.output_extras(),
            provenance=provenance_of(session, settings),
        )
        sender.send(("done", {"plants": len(result.plants), "warnings": list(result.warnings)}))
    except FieldappError as error:
        sender.send(("error", str(error)))
    except Exception as error:  # reported to the caller, whose log keeps the details
        sender.send(("error", f"unexpected error ({type(error).__name__}): {error}"))
    finally:
        if early is not None:
            early.close()
        sender.close()
