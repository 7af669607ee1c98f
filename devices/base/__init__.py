"""The mobile base over ZeroMQ (fieldapp-base/1): protocol, client, simulated base, ROS bridge.

The application uses :class:`BaseClient`; tests and demos serve the protocol with
:class:`SimulatedBase`; the robot runs ``devices.base.ros_bridge``.
"""

from devices.base.client import BaseClient, BaseInfo, ClientTiming
from devices.base.errors import (
    BaseAuthRejected,
    BaseError,
    BaseOffline,
    BaseRequestRejected,
    BaseStopped,
    InsecureEndpoint,
    KeyFileError,
    NavigationFailed,
)
from devices.base.keys import ClientKeys, ServerKeys, generate_key_pair
from devices.base.protocol import BaseState, Pose, Status
from devices.base.simulator import SimFault, SimulatedBase

__all__ = [
    "BaseAuthRejected",
    "BaseClient",
    "BaseError",
    "BaseInfo",
    "BaseOffline",
    "BaseRequestRejected",
    "BaseState",
    "BaseStopped",
    "ClientKeys",
    "ClientTiming",
    "InsecureEndpoint",
    "KeyFileError",
    "NavigationFailed",
    "Pose",
    "ServerKeys",
    "SimFault",
    "SimulatedBase",
    "Status",
    "generate_key_pair",
]
