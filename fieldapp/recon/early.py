"""A plot's stations read by a process forked at start-up, while this one imports the rest.

``fieldapp reconstruct`` spends its first 0.3 s importing SciPy, small_gicp and the stages on
one core, and reading the stations (decoding the PNGs, colour keys, back-projection) needs none
of them: numpy and OpenCV only (:mod:`fieldapp.recon.scans`, :mod:`fieldapp.recon.exg`). So
:meth:`EarlyStations.start`, called once the session and the settings are loaded, forks one
reader that takes the stations from the front of the list, one at a time, while this process
imports; when the pipeline's first stage starts, this process takes them from the back until
the two meet (:meth:`EarlyStations.read`). A thread could not do this: the imports hold the
interpreter, and decoding on a thread beside them slowed them by as much as it gained (issue
22, "Tried, not kept").

Every station is :func:`~fieldapp.recon.scans.read_station` of the same arguments wherever it
runs, and its result does not depend on the thread count, so the scans, their warnings (each
capture skipped) and every output are those of one process. A station's scan comes back
pickled over a pipe (2.0-2.5 MB for a seedling station); the reader's own thread writes them, so
it never waits for this process to finish importing. Which side has a station is decided under
a lock on a shared pair of counters (a ``memfd``, ``lockf``: released by the kernel when the
reader dies).

Failures are this process's, as before: a station the reader could not read (any exception),
or had taken when it died, is read here, in station order after the others, so an exception
is raised here from the same call as without the reader, and the first station's that raises
is the one raised. A reader that cannot be started (no ``fork``, no ``memfd``, a process
limit) means the stations are read as before. The reader is forked with ``os.fork`` (the GUI's
reconstruction process is a daemonic ``multiprocessing`` child, which that module forbids
children) and leaves by ``os._exit``, never through this process's exit handlers; it is killed
if the reconstruction ends before its stations are taken (an error, a cancel).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import os
import pickle
import signal
import struct
import threading
import time
import warnings
from collections.abc import Callable, Generator
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from fieldapp.io.calibration import Calibration
from fieldapp.io.session import Capture, Session
from fieldapp.recon.backproject import ray_table, rig_crop
from fieldapp.recon.scans import StationScan, captures_by_station, carries_plant, read_station
from fieldapp.recon.settings import CropSettings, ReconstructionSettings

log = logging.getLogger(__name__)

StationRead = tuple[StationScan | None, list[str]]
"""What :func:`~fieldapp.recon.scans.read_station` returns: the scan and its warnings."""

READER_STALL_S = 30.0
"""How long this process, with nothing left to read itself, waits for the reader's next
station before it takes the reader for hung (a lock some thread held when it was forked, a file
that does not answer) and kills it: its stations are then read here. A station takes 0.1-0.5 s
to read on the machines measured."""
POLL_S = 0.05
"""How often the wait for the reader looks at the clock."""


def can_fork_a_reader() -> bool:
    """Whether this platform can fork and share the claims (Linux: ``fork``, ``memfd``)."""
    return hasattr(os, "fork") and hasattr(os, "memfd_create")


@dataclass(frozen=True)
class ReadArguments:
    """The settings a station is read with (:func:`~fieldapp.recon.scans.read_station`)."""

    crop: CropSettings
    exg_threshold: float | Literal["otsu"]
    soil_pixel_stride: int


def read_arguments(settings: ReconstructionSettings, calibration: Calibration) -> ReadArguments:
    """The arguments ``settings`` reads stations of a session calibrated by ``calibration``
    with (the crop scaled to its rig, :func:`~fieldapp.recon.backproject.rig_crop`)."""
    filters, ground = settings.filters, settings.ground
    crop = rig_crop(settings.crop, calibration)
    return ReadArguments(crop, filters.exg_threshold, ground.soil_pixel_stride)


def start_reading(session: Session, settings: ReconstructionSettings) -> EarlyStations | None:
    """A reader forked now that starts on ``session``'s stations, for
    :func:`fieldapp.recon.pipeline.reconstruct`'s ``early`` (``None`` where there is none:
    see :meth:`EarlyStations.start`). Call it before importing the pipeline."""
    arguments = read_arguments(settings, session.calibration)
    return EarlyStations.start(session, arguments, settings.threads)


class _Claims:
    """Which stations are taken: the next from the front, the next from the back, in shared
    memory, changed under a ``lockf`` lock (per process, released when its holder dies)."""

    def __init__(self, count: int) -> None:
        import mmap

        self._fd = os.memfd_create("fieldapp-stations")
        os.ftruncate(self._fd, 16)
        self._map = mmap.mmap(self._fd, 16)
        struct.pack_into("<qq", self._map, 0, 0, count - 1)

    def take(self, front: bool) -> int | None:
        """The index of the station taken from the ``front`` (else the back), or ``None`` when
        every station is taken."""
        import fcntl

        fcntl.lockf(self._fd, fcntl.LOCK_EX)
        try:
            first, last = struct.unpack_from("<qq", self._map, 0)
            if first > last:
                return None
            struct.pack_into(
                "<qq", self._map, 0, *((first + 1, last) if front else (first, last - 1))
            )
            return int(first if front else last)
        finally:
            fcntl.lockf(self._fd, fcntl.LOCK_UN)

    def taken_from_front(self) -> int:
        """How many stations were taken from the front (indices 0 to this, exclusive)."""
        import fcntl

        fcntl.lockf(self._fd, fcntl.LOCK_EX)
        try:
            return int(struct.unpack_from("<q", self._map, 0)[0])
        finally:
            fcntl.lockf(self._fd, fcntl.LOCK_UN)

    def close(self) -> None:
        self._map.close()
        os.close(self._fd)


class EarlyStations:
    """One forked reader of a session's stations; use :meth:`start`, then :meth:`read` once,
    then :meth:`close` (also when :meth:`read` was never called)."""

    def __init__(
        self,
        pid: int,
        connection: Connection,
        claims: _Claims,
        session: Session,
        stations: list[tuple[int, list[Capture]]],
        arguments: ReadArguments,
        rays: NDArray[np.float64],
    ) -> None:
        self._pid: int | None = pid
        self._connection = connection
        self._claims = claims
        self._session = session
        self._stations = stations
        self.arguments = arguments
        self._rays = rays
        self._left = False  # the reader's end of the pipe has closed: it is leaving
        self._keep: Callable[[StationScan], StationScan] | None = None
        self._messages = 0  # stations the reader has sent (read or failed)
        self.clock: Callable[[], float] = time.monotonic
        self.stall_s = READER_STALL_S

    @classmethod
    def start(
        cls,
        session: Session,
        arguments: ReadArguments,
        threads: int,
        fork: Callable[[], bool] = can_fork_a_reader,
    ) -> EarlyStations | None:
        """A reader forked now for ``session``'s stations, or ``None`` where there is none to
        start: ``threads`` 1 (one core's work), a plant on a turntable (read otherwise), a
        calibration without a view step, fewer than two stations, or a system that cannot."""
        grouped = captures_by_station(session)
        if (
            threads < 2
            or len(grouped) < 2
            or carries_plant(session)
            or session.calibration.view_step is None
            or not fork()
        ):
            return None
        try:
            rays = ray_table(session.calibration.depth_camera.intrinsics())
        except Exception as error:  # the pipeline meets it where it did, and says so there
            log.debug("stations read in one process: no ray table (%s)", error)
            return None
        stations = list(grouped.items())
        try:
            claims = _Claims(len(stations))
        except OSError as error:
            log.info("stations read in one process: no shared claims (%s)", error)
            return None
        try:
            receive_fd, send_fd = os.pipe()
            with warnings.catch_warnings():  # as in forkmap: the reader takes no lock
                warnings.simplefilter("ignore", DeprecationWarning)
                pid = os.fork()
        except OSError as error:
            log.info("stations read in one process: no reader could be started (%s)", error)
            claims.close()
            return None
        if pid == 0:  # the reader: read from the front, then leave without the exit handlers
            code = 1
            try:
                os.close(receive_fd)
                _read_from_front(session, stations, arguments, rays, claims, send_fd)
                code = 0
            finally:
                os._exit(code)
        os.close(send_fd)
        connection = Connection(receive_fd, writable=False)
        return cls(pid, connection, claims, session, stations, arguments, rays)

    @property
    def station_count(self) -> int:
        return len(self._stations)

    @property
    def pid(self) -> int | None:
        """The reader's process id while it has not been reaped."""
        return self._pid

    def serves(self, session: Session, arguments: ReadArguments) -> bool:
        """Whether this reader reads ``session``'s stations with ``arguments``."""
        return (
            session is self._session
            and arguments == self.arguments
            and list(captures_by_station(session).items()) == self._stations
        )

    def read(
        self, threads: int, keep: Callable[[StationScan], StationScan] | None = None
    ) -> Generator[int, None, dict[int, StationRead]]:
        """Every station read, by station in order: those the reader sends, the others read
        here from the back (on one thread while the reader runs), then those the reader did
        not deliver (it failed or died; on ``threads`` threads). Yields each station as it is
        done (for progress). Raises the first station's exception, in station order. ``keep``:
        what is kept of each scan, called as it arrives (the pipeline levels and filters it
        there and keeps it without its green points)."""
        done: dict[int, StationRead] = {}
        self._keep = keep
        failed: dict[int, Exception] = {}
        while True:
            yield from self._receive(done, wait=False)
            index = self._claims.take(front=False)
            if index is None:
                break
            try:
                read = self._read_here(index, 1)
            except Exception as error:  # raised below, in station order
                failed[index] = error
            else:
                done[index] = self._kept(read)
            yield self._stations[index][0]
        yield from self._await_reader(done)  # until it has sent all and left, or stalls
        self.close()
        for index in range(len(self._stations)):
            if index in failed:
                raise failed[index]
            if index not in done:  # the reader could not read it, or died holding it
                done[index] = self._kept(self._read_here(index, threads))
                yield self._stations[index][0]
        return {self._stations[index][0]: done[index] for index in range(len(self._stations))}

    def _kept(self, read: StationRead) -> StationRead:
        """What is kept of a station read: its scan passed through :meth:`read`'s ``keep``."""
        scan, warnings = read
        if self._keep is None or scan is None:
            return read
        return self._keep(scan), warnings

    def _read_here(self, index: int, threads: int) -> StationRead:
        station, captures = self._stations[index]
        a = self.arguments
        return read_station(
            self._session,
            station,
            captures,
            a.crop,
            a.exg_threshold,
            a.soil_pixel_stride,
            self._rays,
            threads,
        )

    def _await_reader(self, done: dict[int, StationRead]) -> Generator[int, None, None]:
        """The reader's stations until its pipe closes, into ``done``; yields each received.
        When none comes for ``stall_s`` (by ``clock``) the reader is taken for hung: the wait
        ends (:meth:`close` kills it) and what it had not sent is read here."""
        last = self.clock()
        while True:
            received = self._messages
            yield from self._receive(done, wait=False)
            if self._left:
                return
            if self._messages > received:
                last = self.clock()
            elif self.clock() - last > self.stall_s:
                log.warning(
                    "the station reader (pid %s) sent nothing for %.0f s: stopped; its "
                    "stations are read here",
                    self._pid,
                    self.stall_s,
                )
                return
            self._connection.poll(POLL_S)

    def _receive(self, done: dict[int, StationRead], wait: bool) -> Generator[int, None, None]:
        """The reader's stations waiting on the pipe (``wait``: until it closes), into ``done``;
        yields each station received."""
        try:
            while wait or self._connection.poll(0):
                index, read = pickle.loads(self._connection.recv_bytes())
                self._messages += 1
                if read is not None:
                    done[index] = self._kept(read)
                    yield self._stations[index][0]
        except (EOFError, OSError):  # the reader has left (or died): nothing more comes
            self._left = True

    def close(self) -> None:
        """Reap the reader: awaited when its pipe has closed (it is leaving), else killed (it
        holds nothing to clean up); free the pipe and the claims."""
        if self._pid is None:
            return
        pid, self._pid = self._pid, None
        self._connection.close()
        with contextlib.suppress(ChildProcessError):
            if not self._left:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        self._claims.close()


OUTBOX_BYTES = 64 << 20
"""The reader reads no further ahead while this much of what it read waits to be sent (a
depth-only station is 40-50 MB pickled: all of a plot's were queued while the pipeline
imported, and the reader peaked at 364 MB on a 3 x 3 plot)."""


class Outbox:
    """Messages from the reading thread to the sending one, at most ``limit`` bytes of them
    waiting or being sent (one message, whatever its size, when none is). :meth:`close`
    (the receiver has gone) wakes a reader waiting for room."""

    def __init__(self, limit: int) -> None:
        self._limit = limit
        self._messages: collections.deque[bytes | None] = collections.deque()
        self._pending = 0  # bytes put and not yet sent
        self._changed = threading.Condition()
        self.closed = threading.Event()

    def put(self, message: bytes) -> None:
        """Queue ``message`` once there is room for it (or the outbox is closed: dropped)."""
        with self._changed:
            self._changed.wait_for(
                lambda: (
                    self.closed.is_set()
                    or self._pending == 0
                    or self._pending + len(message) <= self._limit
                )
            )
            if self.closed.is_set():
                return
            self._messages.append(message)
            self._pending += len(message)
            self._changed.notify_all()

    def finish(self) -> None:
        """No more messages: :meth:`get` returns ``None`` after the last."""
        with self._changed:
            self._messages.append(None)
            self._changed.notify_all()

    def get(self) -> bytes | None:
        """The next message (waiting for one), ``None`` when finished or closed."""
        with self._changed:
            self._changed.wait_for(lambda: bool(self._messages) or self.closed.is_set())
            if self.closed.is_set():
                return None
            return self._messages.popleft()

    def sent(self, size: int) -> None:
        """A message of ``size`` bytes has left: its room is free."""
        with self._changed:
            self._pending -= size
            self._changed.notify_all()

    def close(self) -> None:
        """The receiver has gone: nothing more is queued or sent."""
        with self._changed:
            self.closed.set()
            self._changed.notify_all()


def _read_from_front(
    session: Session,
    stations: list[tuple[int, list[Capture]]],
    arguments: ReadArguments,
    rays: NDArray[np.float64],
    claims: _Claims,
    send_fd: int,
) -> None:
    """The reader's work: take stations from the front until none is left, read each on one
    thread and send ``(index, (scan, warnings))``, or ``(index, None)`` when it raised; a
    thread of its own writes to the pipe, so reading goes on while this process imports."""
    connection = Connection(send_fd, readable=False)
    outbox = Outbox(OUTBOX_BYTES)
    gone = outbox.closed

    def send() -> None:
        while (message := outbox.get()) is not None:
            try:
                connection.send_bytes(message)
            except OSError:  # this process has closed its end: stop reading
                outbox.close()
                return
            outbox.sent(len(message))

    sender = threading.Thread(target=send, name="early-stations")
    sender.start()
    while not gone.is_set() and (index := claims.take(front=True)) is not None:
        station, captures = stations[index]
        try:
            read = read_station(
                session,
                station,
                captures,
                arguments.crop,
                arguments.exg_threshold,
                arguments.soil_pixel_stride,
                rays,
                1,
            )
            message = pickle.dumps((index, read), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # read again in this process, which raises it as before
            message = pickle.dumps((index, None))
        outbox.put(message)
    outbox.finish()
    sender.join()
    connection.close()
