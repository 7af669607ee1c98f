"""The mobile base over ZeroMQ (fieldapp-base/1): protocol, client, simulated base, ROS bridge.

The application uses :class:`BaseClient`, handed a :class:`BaseTransport` (:func:`open_base`
makes both from endpoints); tests and demos serve the protocol with :class:`SimulatedBase`; the
robot runs ``devices.base.ros_bridge``.
"""

from devices.base.client import BaseClient, BaseInfo, ClientTiming, open_base
from devices.base.errors import (
    BaseAuthRejected,
    BaseError,
    BaseOffline,
    BaseRequestRejected,
    BaseStopped,
    InsecureEndpoint,
    KeyFileError,
    LinkClosed,
    NavigationFailed,
)
from devices.base.keys import ClientKeys, ServerKeys, generate_key_pair
from devices.base.protocol import BaseState, Pose, Status
from devices.base.simulator import SimFault, SimulatedBase
from devices.base.transport import BaseTransport, ZmqTransport, open_transport

__all__ = [
    "BaseAuthRejected",
    "BaseClient",
    "BaseError",
    "BaseInfo",
    "BaseOffline",
    "BaseRequestRejected",
    "BaseState",
    "BaseStopped",
    "BaseTransport",
    "ClientKeys",
    "ClientTiming",
    "InsecureEndpoint",
    "KeyFileError",
    "LinkClosed",
    "NavigationFailed",
    "Pose",
    "ServerKeys",
    "SimFault",
    "SimulatedBase",
    "Status",
    "ZmqTransport",
    "generate_key_pair",
    "open_base",
    "open_transport",
]
