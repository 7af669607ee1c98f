"""Fixtures: simulated Grbl controllers on real pseudo-terminals, and drivers connected to them."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest
import serial

from devices.table import GrblSimulator, GrblTable, PtyGrblServer, TableTimeouts

from ..fake_clock import FakeClock, wait_real

FAST = TableTimeouts(
    banner_s=0.5, reply_s=0.5, status_s=0.2, move_margin_s=0.5, hold_s=3.0, poll_s=0.05
)
"""Short bounds so fault tests finish quickly; the simulator answers within milliseconds."""

QUICK_TABLE = {110: 1800.0, 120: 60.0}
"""30 deg/s, 60 deg/s^2: a 20 degree move takes 1.17 s in real time."""


def connect(
    server: PtyGrblServer,
    timeouts: TableTimeouts = FAST,
    clock: Callable[[], float] = time.monotonic,
) -> GrblTable:
    port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=0.05)
    table = GrblTable(port, timeouts=timeouts, clock=clock)
    table.connect()
    return table


def goto_in_background(
    table: GrblTable, target_deg: float
) -> tuple[threading.Thread, list[BaseException]]:
    """Start ``table.goto_deg(target_deg)`` on a thread, for a test to interrupt. The list
    receives the error it raised, or an AssertionError if the move was reported done."""
    outcome: list[BaseException] = []

    def move() -> None:
        try:
            table.goto_deg(target_deg)
        except BaseException as error:
            outcome.append(error)
        else:
            outcome.append(AssertionError("the move was reported done"))

    mover = threading.Thread(target=move, daemon=True)
    mover.start()
    return mover, outcome


def advance_while_polling(
    table: GrblTable,
    clock: FakeClock,
    worker: threading.Thread,
    step_s: float,
    limit_s: float,
    answer_wait_s: float = 2.0,
) -> float:
    """Advance ``clock`` by ``step_s`` each time the driver's last status poll was answered
    (or when none came within ``answer_wait_s`` of real time: keep it generous unless the
    controller is silent), until
    ``worker`` ends or ``limit_s`` of clock time passed; returns the clock time elapsed. The
    driver never sees its clock jump past an answer that is merely slow in real time."""
    started_s = clock()
    while worker.is_alive() and clock() - started_s < limit_s:
        seen = table.statuses_received
        clock.advance(step_s)
        wait_real(
            lambda seen=seen: table.statuses_received > seen or not worker.is_alive(), answer_wait_s
        )
    worker.join(timeout=20.0)
    return clock() - started_s


@pytest.fixture
def make_server() -> Iterator[Callable[..., PtyGrblServer]]:
    servers: list[PtyGrblServer] = []

    def make(simulator: GrblSimulator | None = None, **kwargs: object) -> PtyGrblServer:
        server = PtyGrblServer(simulator, **kwargs).start()  # type: ignore[arg-type]
        servers.append(server)
        return server

    yield make
    for server in servers:
        server.close()


@pytest.fixture
def make_table() -> Iterator[Callable[..., GrblTable]]:
    tables: list[GrblTable] = []

    def make(
        server: PtyGrblServer,
        timeouts: TableTimeouts = FAST,
        clock: Callable[[], float] = time.monotonic,
    ) -> GrblTable:
        table = connect(server, timeouts, clock)
        tables.append(table)
        return table

    yield make
    for table in tables:
        table.close()


@pytest.fixture
def server(make_server: Callable[..., PtyGrblServer]) -> PtyGrblServer:
    """An instant simulated table."""
    return make_server(GrblSimulator())


@pytest.fixture
def timed_server(make_server: Callable[..., PtyGrblServer]) -> PtyGrblServer:
    """A simulated table moving in real time (30 deg/s, 60 deg/s^2)."""
    return make_server(GrblSimulator(settings=QUICK_TABLE), time_scale=1.0)


@pytest.fixture
def table(server: PtyGrblServer, make_table: Callable[..., GrblTable]) -> GrblTable:
    return make_table(server)
