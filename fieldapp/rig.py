"""The rig: camera, rotary table and mobile base opened together from :class:`DeviceSettings`.

Each device is either real or simulated, and says which (:meth:`Rig.devices`). Simulated
devices are reached through their real drivers over their real transports, and share ONE
:class:`~devices.sim.world.SimWorld`:

- table: a :class:`~devices.table.GrblSimulator` served on a pseudo-terminal
  (:class:`~devices.table.PtyGrblServer`), opened by :func:`~devices.table.open_table` on the
  pty path; its ``on_angle`` sets the world's table angle.
- base: a :class:`~devices.base.SimulatedBase` on loopback (free ports), reached by a
  :class:`~devices.base.BaseClient` over ZeroMQ; its ``on_pose`` (map frame, the frame of
  ``devices.sim.rig``: origin at station 1, station 5 at (1.6, 1.6)) sets the world's base pose.
  It starts where the world's rig starts: at the reference station.
- camera: ``make_camera("sim", world=...)`` looks at the same world.

``realtime`` (default: ``DeviceSettings.realtime_simulation``) moves the simulators at real speed
(demos); otherwise they move at once (tests). :meth:`Rig.close` stops every thread, pty and
socket. A device that cannot be reached raises :class:`RigError` naming it, with advice.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from fieldapp.errors import FieldappError
from fieldapp.settings import DeviceSettings

if TYPE_CHECKING:
    from devices.base import BaseClient, SimulatedBase
    from devices.base.protocol import Pose
    from devices.camera import DepthCamera
    from devices.sim.world import SimWorld
    from devices.table import GrblSimulator, GrblTable, ParkFile, PtyGrblServer

log = logging.getLogger(__name__)

LOOPBACK_ANY_PORT = "tcp://127.0.0.1:*"
INSTANT_BASE_TIME_SCALE = 1000.0
"""Simulated seconds per real second of the simulated base when not in real time."""
SIM_TABLE_OFF_TARGET_DEG = 0.05
"""How far the simulated table may stop from its target (a worm gear's backlash)."""
TABLE_PARK_FILE = "table-park.json"
"""In the user's state folder: where each real table's port was left (:func:`table_park_file`)."""


class RigError(FieldappError):
    """A device of the rig could not be opened or reached; the text names it and says what to
    do."""


@dataclass(frozen=True)
class DeviceSummary:
    """What the operator is told about one device: ``name`` (camera, table, base), whether it
    is simulated, and where it is (backend, port, endpoint)."""

    name: str
    simulated: bool
    where: str

    def __str__(self) -> str:
        kind = "simulated" if self.simulated else "real"
        return f"{self.name}: {kind} ({self.where})"


@dataclass
class Rig:
    """The open devices of one rig. Close it (or use it as a context manager) when done.

    ``world``, ``sim_table`` (with ``table_server``, its pty) and ``sim_base`` are the
    simulators behind simulated devices (``None`` for real ones), for demos and fault injection.
    """

    camera: DepthCamera
    table: GrblTable
    base: BaseClient
    camera_simulated: bool
    table_where: str
    base_where: str
    world: SimWorld | None = None
    sim_table: GrblSimulator | None = None
    table_server: PtyGrblServer | None = None
    sim_base: SimulatedBase | None = None
    realtime: bool = False
    _closers: ExitStack = field(default_factory=ExitStack, repr=False)

    @property
    def table_simulated(self) -> bool:
        return self.sim_table is not None

    @property
    def base_simulated(self) -> bool:
        return self.sim_base is not None

    @property
    def simulated(self) -> bool:
        """True when any device is simulated."""
        return self.camera_simulated or self.table_simulated or self.base_simulated

    def devices(self) -> list[DeviceSummary]:
        info = self.camera.info
        return [
            DeviceSummary("camera", self.camera_simulated, f"{info.backend}, {info.model}"),
            DeviceSummary("table", self.table_simulated, self.table_where),
            DeviceSummary("base", self.base_simulated, self.base_where),
        ]

    def close(self) -> None:
        """Close drivers then simulators: threads joined, pty and sockets released. Safe twice."""
        self._closers.close()
        log.info("rig closed")

    def __enter__(self) -> Rig:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def open_rig(
    devices: DeviceSettings | None = None,
    *,
    realtime: bool | None = None,
    world: SimWorld | None = None,
    seed: int = 0,
    day: int = 0,
) -> Rig:
    """Open the camera, table and base ``devices`` names (defaults: all simulated).

    ``world``: the simulated world (default: the embedded plot of ``seed`` on ``day``), made
    only when a device is simulated. Raises :class:`RigError` when a device cannot be opened;
    whatever was already open is closed again.
    """
    devices = devices or DeviceSettings()
    realtime = devices.realtime_simulation if realtime is None else realtime
    needs_world = (
        devices.camera_backend == "sim" or devices.table_port is None or not devices.base_endpoint
    )
    if world is None and needs_world:
        from devices.sim.world import SimWorld

        world = SimWorld.default(seed=seed, day=day)
    with ExitStack() as stack:
        table_server, table, table_where = _open_table(devices, world, realtime, stack)
        sim_base, base, base_where = _open_base(devices, world, realtime, stack)
        camera = _open_camera(devices, world, realtime, stack)
        rig = Rig(
            camera=camera,
            table=table,
            base=base,
            camera_simulated=camera.info.simulated,
            table_where=table_where,
            base_where=base_where,
            world=world,
            sim_table=None if table_server is None else table_server.simulator,
            table_server=table_server,
            sim_base=sim_base,
            realtime=realtime,
            _closers=stack.pop_all(),
        )
    for summary in rig.devices():
        log.info("rig %s", summary)
    return rig


def _open_table(
    devices: DeviceSettings, world: SimWorld | None, realtime: bool, stack: ExitStack
) -> tuple[PtyGrblServer | None, GrblTable, str]:
    from devices.table import GrblSimulator, PtyGrblServer, TableException, open_table

    server: PtyGrblServer | None = None
    port = devices.table_port
    if port is None:
        if world is None:
            raise RigError("table: a simulated table needs the simulated world")
        simulator = GrblSimulator(
            off_target_deg=SIM_TABLE_OFF_TARGET_DEG, on_angle=world.set_table_angle_deg
        )
        world.set_table_angle_deg(simulator.angle_deg)  # the world follows from the start
        server = PtyGrblServer(simulator, time_scale=1.0 if realtime else 0.0)
        server.start()
        stack.callback(server.close)
        port = server.device_path
    try:
        table = open_table(port, park_file=table_park_file(port) if server is None else None)
    except TableException as error:
        raise RigError(
            f"table on {port}: {error}. Check that the controller is powered and plugged in, "
            f"and that devices.table_port is right (try `fieldapp table --port {port} status`)"
        ) from error
    stack.callback(table.close)
    where = f"Grbl on {port}" if server is None else f"simulated Grbl on {port}"
    return server, table, where


def table_park_file(port: str) -> ParkFile | None:
    """Where a real table's port was left (parked at machine zero or moved), kept in the
    user's state folder: a board reset by opening its port counts its angles from where the
    table stands (``devices.table.park``). None for a pseudo-terminal (a simulator: no DTR)."""
    import platformdirs

    from devices.table import ParkFile

    if port.startswith("/dev/pts/"):
        return None
    return ParkFile(Path(platformdirs.user_state_dir("fieldapp")) / TABLE_PARK_FILE)


def _open_base(
    devices: DeviceSettings, world: SimWorld | None, realtime: bool, stack: ExitStack
) -> tuple[SimulatedBase | None, BaseClient, str]:
    from devices.base import BaseError, ClientKeys, SimulatedBase, open_base
    from devices.base.protocol import Pose

    simulator: SimulatedBase | None = None
    endpoint = devices.base_endpoint
    telemetry = telemetry_endpoint(endpoint) if endpoint else None
    try:
        if not endpoint:
            if world is None:
                raise RigError("base: a simulated base needs the simulated world")
            start = world.base_pose()
            simulator = SimulatedBase(
                LOOPBACK_ANY_PORT,
                LOOPBACK_ANY_PORT,
                time_scale=1.0 if realtime else INSTANT_BASE_TIME_SCALE,
                start=Pose(start.x_m, start.y_m, start.yaw_deg),
            )
            simulator.on_pose.connect(_world_follower(world))
            simulator.start()
            stack.callback(simulator.close)
            endpoint, telemetry = simulator.command_endpoint, simulator.telemetry_endpoint
        keys = ClientKeys.from_dir(devices.base_keys_dir) if devices.base_keys_dir else None
        client = open_base(endpoint, telemetry, keys=keys)
        stack.callback(client.close)
        info = client.hello()
    except BaseError as error:
        raise RigError(
            f"base at {endpoint}: {error}. Check that the base is on, its fieldapp bridge is "
            "running, the network reaches it, and devices.base_endpoint/base_keys_dir are right "
            f"(try `fieldapp base --endpoint {endpoint} hello`)"
        ) from error
    if info.frame != "map":
        raise RigError(f"base at {endpoint}: poses are in frame {info.frame!r}, expected 'map'")
    where = f"{info.name} at {endpoint}"
    return simulator, client, where if simulator is None else f"simulated, {where}"


def _world_follower(world: SimWorld) -> Callable[[Pose], None]:
    def follow(pose: Pose) -> None:
        world.set_base_pose(pose.x_m, pose.y_m, pose.yaw_deg)

    return follow


def _open_camera(
    devices: DeviceSettings, world: SimWorld | None, realtime: bool, stack: ExitStack
) -> DepthCamera:
    from devices.camera import CameraError
    from devices.camera.factory import make_camera

    try:
        camera = make_camera(
            devices.camera_backend, world=world, realtime=realtime, session=devices.replay_session
        )
        camera.open()
    except CameraError as error:
        raise RigError(
            f"camera ({devices.camera_backend}): {error}. Check the camera's cable and power, "
            "and devices.camera_backend (try `fieldapp camera info`)"
        ) from error
    stack.callback(camera.close)
    return camera


def telemetry_endpoint(command_endpoint: str) -> str | None:
    """The telemetry endpoint beside a ``tcp://host:port`` command endpoint: the next port
    (the spec's 5555/5556); ``None`` when the port is not a number."""
    head, _, port = command_endpoint.rpartition(":")
    if not command_endpoint.startswith("tcp://") or not port.isdigit():
        return None
    return f"{head}:{int(port) + 1}"
