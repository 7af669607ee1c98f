"""Serve a :class:`GrblSimulator` on a pseudo-terminal, so the driver opens it like a USB port.

The slave side (``device_path``, e.g. ``/dev/pts/7``) is in raw mode; the server thread reads
the master, feeds the simulator, moves its time (``time_scale`` 0: instant; 1: real time) and
writes its output back. :meth:`PtyGrblServer.unplug` closes the master under the driver's
feet, as pulling the USB cable does.

Opening a real board's port resets it through DTR (the banner follows). A pty has no DTR, but
the master runs in packet mode and sees the input flush every pyserial ``open()`` does; with
``reset_on_open`` the simulator is then powered on again (banner; the table angle is kept).
"""

from __future__ import annotations

import errno
import fcntl
import logging
import math
import os
import select
import struct
import termios
import threading
import time
import tty
from types import TracebackType

from devices.table.simulator import GrblSimulator

log = logging.getLogger(__name__)


class PtyGrblServer:
    """One simulated controller on one pty. Use as a context manager or call start/close."""

    def __init__(
        self,
        simulator: GrblSimulator | None = None,
        *,
        time_scale: float = 0.0,
        tick_s: float = 0.005,
        reset_on_open: bool = True,
    ) -> None:
        if time_scale < 0.0:
            raise ValueError(f"time_scale must be >= 0, got {time_scale}")
        self.simulator = simulator or GrblSimulator()
        self.time_scale = time_scale
        self.tick_s = tick_s
        self.reset_on_open = reset_on_open
        self._master_fd = -1
        self._slave_fd = -1
        self.device_path = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, *, power_on: bool = False) -> PtyGrblServer:
        """Open the pty and serve; with ``power_on`` the banner is sent right away."""
        self._master_fd, self._slave_fd = os.openpty()
        tty.setraw(self._slave_fd)
        os.set_blocking(self._master_fd, False)
        fcntl.ioctl(self._master_fd, termios.TIOCPKT, struct.pack("i", 1))
        self.device_path = os.ttyname(self._slave_fd)
        if power_on:
            self.simulator.power_on()
        self._thread = threading.Thread(target=self._serve, name="grbl-sim-pty", daemon=True)
        self._thread.start()
        log.info("simulated Grbl table on %s (time scale %s)", self.device_path, self.time_scale)
        return self

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def power_on(self) -> None:
        """Power the controller up (banner), as plugging the board in does."""
        self.simulator.power_on()

    def unplug(self) -> None:
        """Pull the cable: the driver's next read or write on the slave fails."""
        log.info("unplugging simulated table %s", self.device_path)
        self.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        for fd in (self._master_fd, self._slave_fd):
            if fd >= 0:
                os.close(fd)
        self._master_fd = self._slave_fd = -1

    def __enter__(self) -> PtyGrblServer:
        return self if self.running else self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _serve(self) -> None:
        last_s = time.monotonic()
        while not self._stop.is_set():
            readable, _, _ = select.select([self._master_fd], [], [], self.tick_s)
            if readable:
                self.simulator.receive(self._read())
            now_s = time.monotonic()
            dt_s = math.inf if self.time_scale == 0.0 else (now_s - last_s) * self.time_scale
            last_s = now_s
            self.simulator.advance(dt_s)
            self._write(self.simulator.take_output())

    def _read(self) -> bytes:
        """Data the host wrote; a packet-mode flush of the slave's input is a port open."""
        try:
            packet = os.read(self._master_fd, 4096)
        except OSError as error:
            if error.errno in (errno.EAGAIN, errno.EIO):
                return b""
            raise
        if not packet:
            return b""
        if packet[0] == termios.TIOCPKT_DATA:
            return packet[1:]
        if packet[0] & termios.TIOCPKT_FLUSHREAD and self.reset_on_open:
            log.debug("port %s opened: controller restarts", self.device_path)
            self.simulator.power_on()
        return b""

    def _write(self, data: bytes) -> None:
        while data:
            try:
                written = os.write(self._master_fd, data)
            except BlockingIOError:
                log.warning(
                    "pty full (nobody reading %s): dropped %d bytes", self.device_path, len(data)
                )
                return
            data = data[written:]
