"""``fieldapp base --endpoint EP [hello | status | goto X Y YAW | cancel ID | stop | reset]``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from devices.base.client import BaseClient


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "base",
        help="talk to the mobile base (hello, status, goto, cancel, stop, reset)",
        description="Send one command to a base serving fieldapp-base/1 (a robot bridge or "
        "'fieldapp sim-base'). Exit 0 on success, 1 on any failure.",
    )
    parser.add_argument("--endpoint", default="tcp://127.0.0.1:5555", help="command endpoint")
    parser.add_argument("--keys", type=Path, help="folder with client.key_secret and base.key")
    parser.add_argument("--timeout", type=float, default=300.0, help="goto: seconds to wait")
    commands = parser.add_subparsers(dest="base_command", metavar="COMMAND", required=True)
    commands.add_parser("hello", help="name, protocol and map bounds of the base")
    commands.add_parser("status", help="state, goal, pose and battery")
    goto = commands.add_parser("goto", help="drive to X Y (metres, map frame) and YAW (degrees)")
    goto.add_argument("x_m", type=float, metavar="X")
    goto.add_argument("y_m", type=float, metavar="Y")
    goto.add_argument("yaw_deg", type=float, metavar="YAW")
    goto.add_argument("--goal-id", help="default: cli-<time>")
    goto.add_argument("--no-wait", action="store_true", help="return once the goal is accepted")
    cancel = commands.add_parser("cancel", help="cancel a goal; the base stops where it is")
    cancel.add_argument("goal_id")
    commands.add_parser("stop", help="zero velocity now and set the stop latch")
    commands.add_parser("reset", help="clear the stop latch (never starts motion)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from devices.base.client import open_base
    from devices.base.errors import BaseError
    from devices.base.keys import ClientKeys

    try:
        keys = ClientKeys.from_dir(args.keys) if args.keys else None
        with open_base(args.endpoint, keys=keys) as client:
            _execute(client, args)
    except BaseError as error:
        print(f"fieldapp base: {error}", file=sys.stderr)
        return 1
    return 0


def _execute(client: BaseClient, args: argparse.Namespace) -> None:
    from devices.base.protocol import Pose

    command = args.base_command
    if command == "hello":
        info = client.hello()
        print(f"{info.name}: protocol {info.protocol}, frame {info.frame}, bounds {info.bounds_m}")
    elif command == "status":
        _print_status(client.status())
    elif command == "goto":
        goal_id = args.goal_id or f"cli-{int(time.time())}"
        goal = Pose(args.x_m, args.y_m, args.yaw_deg)
        if args.no_wait:
            client.goto(goal_id, goal, wait=False)
            print(f"goal {goal_id} accepted")
            return
        client.goto(goal_id, goal, wait=False)
        last_print_s = 0.0
        for status in client.follow_goal(goal_id, args.timeout):
            if time.monotonic() - last_print_s >= 1.0 or status.state.value != "moving":
                _print_status(status)
                last_print_s = time.monotonic()
    elif command == "cancel":
        print("cancelled" if client.cancel(args.goal_id) else f"goal {args.goal_id} was not active")
    elif command == "stop":
        client.stop()
        print("stopped (latched: 'fieldapp base reset' to clear)")
    elif command == "reset":
        client.reset()
        print("stop latch cleared")


def _print_status(status: Any) -> None:
    pose = status.pose
    line = (
        f"{status.state.value}: goal {status.goal_id}, x {pose.x_m:.3f} m, y {pose.y_m:.3f} m, "
        f"yaw {pose.yaw_deg:.1f} deg, battery {status.battery_pct:.1f} %"
    )
    print(line + (f", error: {status.error}" if status.error else ""))
