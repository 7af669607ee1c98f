"""The verdict on a calibration's quality figures, graded in the core
(:mod:`fieldapp.calib.verdict`); the wizards only show it."""

from fieldapp.calib.verdict import (
    Level,
    Verdict,
    grade,
    ground_verdict,
    intrinsics_verdict,
    stations_verdict,
    views_verdict,
)

__all__ = [
    "Level",
    "Verdict",
    "grade",
    "ground_verdict",
    "intrinsics_verdict",
    "stations_verdict",
    "views_verdict",
]
