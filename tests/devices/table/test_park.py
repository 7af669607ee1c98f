"""Where the table was left: a board reset by opening its port (DTR) is a power-up, and Grbl
then counts its machine position from where the table stands (gnea/grbl main.c)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import serial

from devices.table import (
    GrblSimulator,
    GrblTable,
    ParkFile,
    PtyGrblServer,
    TablePositionUnknown,
)

from .conftest import FAST

PORT = "/dev/ttyUSB0"


@pytest.fixture
def open_driver() -> Iterator[Callable[[PtyGrblServer, ParkFile], GrblTable]]:
    tables: list[GrblTable] = []

    def make(server: PtyGrblServer, park: ParkFile) -> GrblTable:
        port = serial.serial_for_url(server.device_path, baudrate=115200, timeout=0.05)
        table = GrblTable(port, timeouts=FAST, park_file=park, port_name=PORT)
        tables.append(table)
        table.connect()
        return table

    yield make
    for table in tables:
        table.close()


def test_the_park_file_keeps_each_port_s_state(tmp_path: Path, caplog) -> None:
    park = ParkFile(tmp_path / "state" / "table-park.json")
    assert park.state(PORT) is None
    park.record(PORT, "moved")
    park.record("/dev/ttyACM0", "parked")
    assert (park.state(PORT), park.state("/dev/ttyACM0")) == ("moved", "parked")
    assert ParkFile(park.path).state(PORT) == "moved"  # on disk
    park.path.write_text("{not json")
    caplog.set_level(logging.WARNING, logger="devices.table.park")  # whatever a CLI run set
    assert park.state(PORT) is None
    assert "unreadable" in caplog.text and str(park.path) in caplog.text


@pytest.mark.parametrize(("left", "known"), [("moved", False), ("parked", True), (None, True)])
def test_a_power_up_on_opening_is_trusted_only_where_the_table_was_parked(
    make_server: Callable[..., PtyGrblServer],
    open_driver: Callable[[PtyGrblServer, ParkFile], GrblTable],
    tmp_path: Path,
    left: str | None,
    known: bool,
) -> None:
    """A port never seen is trusted (a rig set up at its zero); one last left ``moved`` is not:
    the machine zero the controller restarted with is wherever the table stood."""
    park = ParkFile(tmp_path / "table-park.json")
    if left is not None:
        park.record(PORT, left)  # type: ignore[arg-type]
    server = make_server(GrblSimulator())  # opening the pty powers it up: a banner
    table = open_driver(server, park)
    assert table.restarted_on_open
    assert table.position_known is known
    if not known:
        with pytest.raises(TablePositionUnknown):
            table.goto_deg(45.0)
        table.confirm_position_known()  # the operator turned it to its zero mark by hand
        assert park.state(PORT) == "parked"  # at machine zero: the next power-up keeps it
    assert table.goto_deg(45.0) == pytest.approx(45.0, abs=0.2)
    assert park.state(PORT) == "moved"
    assert table.park() == pytest.approx(0.0, abs=0.2)
    assert park.state(PORT) == "parked"


def test_a_reset_by_the_driver_keeps_the_machine_position(
    make_server: Callable[..., PtyGrblServer],
    open_driver: Callable[[PtyGrblServer, ParkFile], GrblTable],
    tmp_path: Path,
) -> None:
    """No banner as the port opened (no DTR wiring, a simulator): the driver's Ctrl-X is a
    soft reset, which keeps the machine position; nothing to distrust."""
    park = ParkFile(tmp_path / "table-park.json")
    park.record(PORT, "moved")
    quiet = make_server(GrblSimulator(), reset_on_open=False)
    table = open_driver(quiet, park)
    assert not table.restarted_on_open
    assert table.position_known
