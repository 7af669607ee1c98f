"""The rotary table: a Grbl 1.1 controller on a serial port, its driver and its simulator.

- :mod:`devices.table.protocol`: bytes in, bytes out (no I/O).
- :mod:`devices.table.driver`: :class:`GrblTable`, given an open port; :func:`open_table`.
- :mod:`devices.table.park`: :class:`ParkFile`, where each port's table was left.
- :mod:`devices.table.simulator`: :class:`GrblSimulator`, a model of controller and table;
  :mod:`devices.table.pty_server`: :class:`PtyGrblServer` serves it on a pseudo-terminal.
"""

from devices.table.driver import GrblTable, TableStatus, TableTimeouts, open_table
from devices.table.errors import (
    TableAlarm,
    TableDisconnected,
    TableError,
    TableException,
    TableHeld,
    TableMisconfigured,
    TableMissedTarget,
    TablePositionUnknown,
    TableReset,
    TableTimeout,
)
from devices.table.park import ParkFile
from devices.table.pty_server import PtyGrblServer
from devices.table.simulator import GrblSimulator

__all__ = [
    "GrblSimulator",
    "GrblTable",
    "ParkFile",
    "PtyGrblServer",
    "TableAlarm",
    "TableDisconnected",
    "TableError",
    "TableException",
    "TableHeld",
    "TableMisconfigured",
    "TableMissedTarget",
    "TablePositionUnknown",
    "TableReset",
    "TableStatus",
    "TableTimeout",
    "TableTimeouts",
    "open_table",
]
