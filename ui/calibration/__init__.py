"""Calibration wizards (intrinsics, view to view, station to station, ground) and the
Calibrate page that hosts them (:class:`CalibratePage`); :func:`create_page` builds it for
the main window."""

from __future__ import annotations

from typing import Any

from PySide6 import QtWidgets

from ui.calibration.page import CalibratePage, default_calibration_path

__all__ = ["CalibratePage", "create_page"]


def create_page(context: Any) -> QtWidgets.QWidget:
    """The Calibrate page of the main window: the rig's calibration file beside the sessions
    folder, live previews from the hub's camera stream when the devices are connected."""
    hub = getattr(context, "hub", None)
    return CalibratePage(
        default_calibration_path(context.settings),
        stream=lambda: getattr(hub, "stream", None),
        ui_state=getattr(context, "ui_state", None),
    )
