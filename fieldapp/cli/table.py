"""``fieldapp table --port PORT ACTION``: check a rotary table (Grbl 1.1) from a terminal."""

from __future__ import annotations

import argparse
import sys
from typing import Any

ACTIONS = {
    "goto": "turn to DEG degrees and print the angle reached",
    "status": "print the controller state and the table angle",
    "hold": "feed hold (!): stop with controlled deceleration",
    "resume": "cycle start (~): carry on a held move",
    "reset": "soft reset (Ctrl-X): immediate stop; the position is unknown afterwards",
    "home": "run the homing cycle ($H), only when the operator asks",
    "unlock": "clear an alarm lock ($X), only when the operator has checked the table",
    "park": "turn to machine zero, where a controller reset by opening its port keeps the angles",
    "confirm": "the table stands at its zero mark (turned there by hand): trust its position",
}


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "table",
        help="check the rotary table (Grbl controller) from a terminal",
        description="Talk to the rotary table's Grbl 1.1 controller on a serial port: turn to "
        "an angle, print the status, hold, reset, home or unlock. The port is a device path "
        "(/dev/ttyUSB0), a pyserial URL, or the path printed by `fieldapp sim-table`.",
    )
    parser.add_argument("--port", required=True, help="serial device path or pyserial URL")
    parser.add_argument(
        "--timeout",
        type=float,
        default=2.0,
        help="seconds to wait for each answer and for the banner (default and banner max 2)",
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, text in ACTIONS.items():
        action = actions.add_parser(name, help=text, description=text)
        if name == "goto":
            action.add_argument("deg", type=float, help="target angle, degrees")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from devices.table import TableException, TableTimeouts, open_table
    from devices.table.protocol import ProtocolError
    from fieldapp.rig import table_park_file

    timeouts = TableTimeouts(reply_s=args.timeout, banner_s=min(2.0, args.timeout))
    try:
        table = open_table(args.port, timeouts=timeouts, park_file=table_park_file(args.port))
        try:
            print(_act(table, args.action, getattr(args, "deg", 0.0)))
        finally:
            table.close()
    except (TableException, ProtocolError) as error:
        print(f"fieldapp table: {error}", file=sys.stderr)
        return 1
    return 0


def _act(table: Any, action: str, deg: float) -> str:
    if action == "goto":
        return f"table at {table.goto_deg(deg):.3f} deg"
    if action == "hold":
        return f"held: {table.hold()}"
    if action == "resume":
        table.resume()
        return f"resumed: {table.status()}"
    if action == "reset":
        return f"reset: {table.reset()}"
    if action == "home":
        return f"homed: table at {table.home():.3f} deg"
    if action == "unlock":
        return f"unlocked: {table.unlock()}"
    if action == "park":
        return f"parked: table at {table.park():.3f} deg"
    if action == "confirm":
        table.confirm_position_known()
        return f"confirmed: {table.status()}"
    return str(table.status())
