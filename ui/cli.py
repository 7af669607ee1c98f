"""``fieldapp gui``: the field application's window (registered through the
``fieldapp.commands`` entry point, so the core never imports the UI)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "gui",
        help="open the field application window (simulated devices by default)",
        description="Open the field GUI: devices, live preview, missions. With no hardware "
        "configured every device is simulated, and the window says so.",
    )
    parser.add_argument(
        "--settings", type=Path, help="settings file (default: the user's settings.yaml)"
    )
    parser.add_argument(
        "--no-connect", action="store_true", help="do not connect the devices at start-up"
    )
    parser.set_defaults(handler=run)


QT_PACKAGES = frozenset({"PySide6", "shiboken6", "pyqtgraph", "OpenGL"})


def run(args: argparse.Namespace) -> int:
    try:
        from ui.app import run_gui
    except ImportError as error:  # a headless install (no "gui" extra): say how to get it
        if (error.name or "").partition(".")[0] not in QT_PACKAGES:
            raise
        raise FieldappError(
            f"the window needs the GUI packages ({error.name} is not installed): "
            "pip install 'fieldapp[gui]'"
        ) from None

    return run_gui(args.settings, connect=not args.no_connect)
