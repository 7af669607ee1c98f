"""The one small interface every depth camera backend implements, and its typed errors.

A camera is opened, hands out frames one by one (:meth:`DepthCamera.read_frame` blocks until
the next frame and never longer than its timeout), and is closed. Frames follow
:class:`~devices.camera.frames.Frame`: depth in metres (float32, NaN = missing), colour
registered to depth pixel for pixel (uint8 RGB), IR when the sensor has it, a monotonic
timestamp. Live streaming (:mod:`devices.camera.stream`) and quiet captures
(:mod:`devices.camera.capture`) are built on ``read_frame`` alone.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from types import TracebackType

from devices.camera.capture import capture_median
from devices.camera.frames import Frame, Intrinsics

FRAME_TIMEOUT_S = 2.0
"""How long :meth:`DepthCamera.read_frame` waits by default before :class:`CameraTimeout`."""


class CameraError(Exception):
    """Base of every camera error; the text is meant for the operator."""


class CameraUnavailable(CameraError):
    """The backend library or the device is missing, or the device cannot be opened."""


class CameraTimeout(CameraError):
    """No frame arrived within the timeout."""


class CameraDisconnected(CameraError):
    """The device went away (unplugged, power lost) or the camera is closed."""


class CameraFormatError(CameraError):
    """A recorded input (session folder, recording) is unreadable; the text names file/field."""


class CameraEnded(CameraError):
    """A finite source (a replay that does not loop) has no more frames."""


@dataclass(frozen=True)
class CameraInfo:
    """What the operator is told about a camera."""

    backend: str
    model: str
    serial: str
    simulated: bool = False


class DepthCamera(abc.ABC):
    """A depth camera: open, read frames, close. Use as a context manager.

    Subclasses implement :meth:`_open`, :meth:`_close`, :meth:`_read` and the two properties.
    """

    def __init__(self) -> None:
        self._is_open = False

    @property
    def is_open(self) -> bool:
        return self._is_open

    def open(self) -> None:
        """Connect to the device (raises :class:`CameraUnavailable`); no-op when open."""
        if not self._is_open:
            self._open()
            self._is_open = True

    def close(self) -> None:
        """Release the device; safe to call twice."""
        if self._is_open:
            self._is_open = False
            self._close()

    def __enter__(self) -> DepthCamera:
        self.open()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    @property
    @abc.abstractmethod
    def intrinsics(self) -> Intrinsics:
        """The depth image's intrinsics (the colour image is registered to it)."""

    @property
    @abc.abstractmethod
    def info(self) -> CameraInfo:
        """Backend, model and serial number."""

    def read_frame(self, timeout_s: float = FRAME_TIMEOUT_S) -> Frame:
        """The next frame; raises :class:`CameraTimeout` when none arrives within
        ``timeout_s``, :class:`CameraDisconnected` when the camera is closed or gone."""
        if not self._is_open:
            raise CameraDisconnected(f"{self.info.backend} camera is not open")
        return self._read(timeout_s)

    def capture(self, n: int = 5, timeout_s: float = FRAME_TIMEOUT_S) -> Frame:
        """One quiet frame from ``n`` consecutive frames (per-pixel median; see
        :func:`devices.camera.capture.capture_median`)."""
        return capture_median(self.read_frame, n, timeout_s)

    @abc.abstractmethod
    def _open(self) -> None: ...

    @abc.abstractmethod
    def _close(self) -> None: ...

    @abc.abstractmethod
    def _read(self, timeout_s: float) -> Frame: ...
