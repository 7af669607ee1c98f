"""Connection tests for the device settings dialog: open one device, ask it something,
close it, and say what happened. Each runs on a worker thread; none touches Qt.

Simulated devices are tested the same way as real ones: through their real drivers over
their real transports (a pty for the table, loopback ZeroMQ for the base).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fieldapp.settings import DeviceSettings
from ui.notifications import advice_for

log = logging.getLogger(__name__)

CAMERA_PROBE_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class ProbeResult:
    """``ok``: the device answered; ``message`` says what it said or what failed;
    ``advice`` what to do about a failure."""

    device: str
    ok: bool
    message: str
    advice: str = ""


def _failure(device: str, error: BaseException) -> ProbeResult:
    return ProbeResult(device, False, f"{type(error).__name__}: {error}", advice_for(error))


def list_serial_ports() -> list[tuple[str, str]]:
    """(device path, description) of the serial ports present now."""
    from serial.tools import list_ports

    return [(port.device, port.description or "") for port in sorted(list_ports.comports())]


def probe_camera(devices: DeviceSettings) -> ProbeResult:
    """Open the camera, read one frame, close it."""
    from devices.camera import CameraError
    from devices.camera.factory import make_camera

    try:
        world = None
        if devices.camera_backend == "sim":
            from devices.sim.world import SimWorld

            world = SimWorld.default()
        camera = make_camera(
            devices.camera_backend, world=world, realtime=False, session=devices.replay_session
        )
        with camera:
            frame = camera.read_frame(CAMERA_PROBE_TIMEOUT_S)
            info = camera.info
    except (CameraError, ValueError) as error:
        return _failure("camera", error)
    valid = float(np.isfinite(frame.depth_m).mean())
    height, width = frame.depth_m.shape
    return ProbeResult(
        "camera",
        True,
        f"{info.model} ({info.serial}): a {width} x {height} frame, {valid:.0%} valid depth",
    )


def probe_table(port: str | None) -> ProbeResult:
    """Open the table's port (a simulated controller on a pty when ``port`` is None), read
    its status, close it."""
    from devices.table import GrblSimulator, PtyGrblServer, TableException, open_table

    server = PtyGrblServer(GrblSimulator()).start() if port is None else None
    path = server.device_path if server is not None else str(port)
    try:
        table = open_table(path)
        try:
            status = table.status()
        finally:
            table.close()
    except TableException as error:
        return _failure("table", error)
    finally:
        if server is not None:
            server.close()
    kind = "simulated Grbl" if server is not None else "Grbl"
    return ProbeResult("table", True, f"{kind} on {path}: {status}")


def probe_base(endpoint: str | None, keys_dir: Path | None) -> ProbeResult:
    """Say hello to the base (a simulated base on loopback when ``endpoint`` is empty)."""
    from devices.base import BaseError, ClientKeys, SimulatedBase, open_base
    from fieldapp.rig import LOOPBACK_ANY_PORT, telemetry_endpoint

    simulator = None
    try:
        if not endpoint:
            simulator = SimulatedBase(LOOPBACK_ANY_PORT, LOOPBACK_ANY_PORT).start()
            endpoint = simulator.command_endpoint
        keys = ClientKeys.from_dir(keys_dir) if keys_dir else None
        with open_base(endpoint, telemetry_endpoint(endpoint), keys=keys) as client:
            info = client.hello()
            status = client.status()
    except BaseError as error:
        return _failure("base", error)
    finally:
        if simulator is not None:
            simulator.close()
    kind = "simulated base" if simulator is not None else "base"
    return ProbeResult(
        "base",
        True,
        f"{kind} {info.name!r} at {endpoint}: {status.state.value}, "
        f"battery {status.battery_pct:.0f} %, protocol {info.protocol}",
    )


def probe(device: str, devices: DeviceSettings) -> ProbeResult:
    """Test ``device`` (camera, table or base) as ``devices`` configures it."""
    if device == "camera":
        return probe_camera(devices)
    if device == "table":
        return probe_table(devices.table_port)
    if device == "base":
        return probe_base(devices.base_endpoint, devices.base_keys_dir)
    raise ValueError(f"unknown device {device!r}")
