"""What the operator should do about an error, chosen from its actual cause.

A device driver wraps the low-level failure in its typed error (``CameraUnavailable``,
``TableDisconnected``...); the advice follows what really went wrong underneath: a Python
library that is not installed is told as such (and where the install steps are), never as a
cable to check. :func:`advice_for` walks the error, its cause and its context.
"""

from __future__ import annotations

import re

DRIVERS: dict[str, str] = {
    "pylibfreenect2": "The Kinect v2 driver (pylibfreenect2) is not installed: see "
    "packaging/README.md (Kinect v2), or choose the simulated camera in Devices...",
    "pyrealsense2": "The RealSense driver (pyrealsense2) is not installed: see "
    "packaging/README.md (RealSense), or choose the simulated camera in Devices...",
    "serial": "The serial-port library (pyserial) is not installed: reinstall fieldapp "
    "(packaging/README.md).",
    "zmq": "The ZeroMQ library (pyzmq) is not installed: reinstall fieldapp (packaging/README.md).",
}
MISSING_MODULE = re.compile(r"No module named '?([A-Za-z0-9_]+)")
INSTALL_HINT = re.compile(r"\bneeds\b[^.:()]*?\b(pylibfreenect2|pyrealsense2)\b")
"""A driver's install hint ("Kinect v2 needs ... pylibfreenect2"), raised without the
ImportError when the driver hides it."""


def _chain(error: BaseException) -> list[BaseException]:
    """``error``, then its causes and contexts (a driver's ``raise ... from None`` keeps the
    original in ``__context__``), each once."""
    seen: list[BaseException] = []
    current: BaseException | None = error
    while current is not None and all(current is not e for e in seen):
        seen.append(current)
        current = current.__cause__ or current.__context__
    return seen


def missing_library(error: BaseException) -> str | None:
    """The top-level name of the Python module whose absence caused ``error``, if any."""
    for link in _chain(error):
        if isinstance(link, ImportError) and link.name:
            return link.name.split(".")[0]
        match = MISSING_MODULE.search(str(link))
        if match:
            return match.group(1)
        match = INSTALL_HINT.search(str(link))
        if match:
            return match.group(1)
    return None


def library_advice(module: str) -> str:
    return DRIVERS.get(
        module,
        f"The Python library {module} is not installed: reinstall fieldapp (packaging/README.md).",
    )


def _by_type(error: BaseException) -> str:
    from devices.base import errors as base
    from devices.camera import base as camera
    from devices.table import errors as table

    advice: list[tuple[type[BaseException], str]] = [
        (table.TableAlarm, "Check the table is free to turn, then Unlock or Home it in "
         "Mission > Set-up."),
        (camera.CameraUnavailable, "Check the camera's USB 3 cable and power, or choose "
         "the simulated camera in Devices..."),
        (camera.CameraDisconnected, "Check the camera's cable and power, then Connect again."),
        (camera.CameraTimeout, "The camera stopped sending frames: reconnect it."),
        (camera.CameraFormatError, "Choose another session folder for the replay camera."),
        (camera.CameraEnded, "The replay reached the end of its session: Connect again to "
         "replay it once more."),
        (table.TableDisconnected, "Check the table's USB cable and choose its port in "
         "Devices..."),
        (table.TableTimeout, "Is the table's controller powered and is this its port?"),
        (table.TableHeld, "Resume or reset the table in Mission > Set-up."),
        (table.TableMissedTarget, "Check nothing blocks the table, then home it."),
        (base.BaseAuthRejected, "The base refused this computer's key: check the key folder "
         "in Devices... and that the base lists this client."),
        (base.KeyFileError, "Choose the folder holding client.key_secret and base.key in "
         "Devices..."),
        (base.InsecureEndpoint, "A base on the network needs CURVE keys: set the key folder "
         "in Devices..."),
        (base.BaseOffline, "Check the base is powered and on the network, and its endpoint "
         "in Devices..."),
        (base.BaseStopped, "The base is stopped: clear the area, then Reset the base."),
        (base.NavigationFailed, "Check the path to the station is clear, then resume."),
    ]  # fmt: skip
    for link in _chain(error):
        for kind, text in advice:
            if isinstance(link, kind):
                return text
    return ""


def advice_for(error: BaseException) -> str:
    """What the operator should do about ``error``: a missing library first (no cable
    fixes that), then the advice for the first typed error in its chain; empty when there
    is nothing to add."""
    module = missing_library(error)
    if module is not None:
        return library_advice(module)
    return _by_type(error)
