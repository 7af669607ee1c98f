"""Depth cameras behind one small interface (frames, intrinsics, capture)."""

from devices.camera.frames import Frame, Intrinsics

__all__ = ["Frame", "Intrinsics"]
