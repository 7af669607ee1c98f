"""Calibration wizards (intrinsics, view to view, station to station, ground) and the
Calibrate page that hosts them (:class:`CalibratePage`)."""

from ui.calibration.page import CalibratePage

__all__ = ["CalibratePage"]
