"""The verdict on a calibration's quality figures: good, usable or redo, and why.

Thresholds follow the paper and the Kinect v2: Zhang's method on its IR images reaches
0.1-0.3 px; the paper's view-to-view feature points fit to 1.8 mm; a station pair through
boards 1-3 mm; the ground plane of tilled soil a few millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from fieldapp.calib.ground import GroundResult
from fieldapp.calib.intrinsics import RECOMMENDED_VIEWS, IntrinsicsResult, missing_regions
from fieldapp.calib.stations import StationsResult
from fieldapp.calib.views import ViewStepResult


class Level(StrEnum):
    """good: use it; usable: use it, better redone; redo: do not use it."""

    GOOD = "good"
    USABLE = "usable"
    REDO = "redo"


@dataclass
class Verdict:
    """The level of a result and the reasons for it."""

    level: Level = Level.GOOD
    reasons: list[str] = field(default_factory=list)

    def worse(self, level: Level, reason: str) -> None:
        """Note ``reason``; the verdict drops to ``level`` if that is worse."""
        order = list(Level)
        if order.index(level) > order.index(self.level):
            self.level = level
        self.reasons.append(reason)

    def text(self) -> str:
        """``Good``, ``Usable`` or ``Redo``, then the reasons."""
        head = {Level.GOOD: "Good", Level.USABLE: "Usable", Level.REDO: "Redo"}[self.level]
        return head + (": " + "; ".join(self.reasons) if self.reasons else "")


def grade(verdict: Verdict, value: float, good: float, usable: float, what: str) -> None:
    """``value`` (smaller is better) against the good and usable limits."""
    if value > usable:
        verdict.worse(Level.REDO, f"{what} above {usable:g}")
    elif value > good:
        verdict.worse(Level.USABLE, f"{what} above {good:g}")


def intrinsics_verdict(result: IntrinsicsResult) -> Verdict:
    """Zhang RMS, number of good views, corner coverage."""
    verdict = Verdict()
    grade(verdict, result.rms_px, 0.3, 0.8, f"RMS reprojection error {result.rms_px:.2f} px")
    used = len(result.used)
    if used < RECOMMENDED_VIEWS:
        level = Level.REDO if used < RECOMMENDED_VIEWS // 2 else Level.USABLE
        verdict.worse(level, f"only {used} good views (take {RECOMMENDED_VIEWS} or more)")
    missing = missing_regions(result.coverage_map)
    if missing:
        level = Level.REDO if len(missing) > 3 else Level.USABLE
        verdict.worse(level, "no corners in the " + ", ".join(missing))
    rejected = [v.name for v in result.views if v.rejected]
    if rejected:
        verdict.reasons.append(f"{len(rejected)} image(s) not used")
    return verdict


def views_verdict(result: ViewStepResult, nominal_deg: float) -> Verdict:
    """Feature RMSE, turn against the angle set, cross-check by several pairs."""
    verdict = Verdict()
    grade(verdict, 1000 * result.rmse_m, 2.0, 5.0, f"feature RMSE {1000 * result.rmse_m:.2f} mm")
    off = abs(abs(result.angle_deg) - abs(nominal_deg))
    grade(verdict, off, 0.5, 2.0, f"turn {result.angle_deg:.2f} degrees vs {nominal_deg:g} set")
    if len(result.pairs) < 2:
        verdict.worse(Level.USABLE, "a single pair of views: nothing to cross-check it")
    return verdict


def stations_verdict(result: StationsResult) -> Verdict:
    """Joint and pairwise RMSE, refused pairs."""
    verdict = Verdict()
    rmse_mm = 1000 * result.bundle.rmse_m
    grade(verdict, rmse_mm, 3.0, 8.0, f"joint RMSE {rmse_mm:.2f} mm")
    for pair in result.pairs:
        grade(
            verdict,
            1000 * pair.fit.rmse_m,
            3.0,
            8.0,
            f"stations {pair.station_a}-{pair.station_b} RMSE {1000 * pair.fit.rmse_m:.2f} mm",
        )
    if result.warnings:
        verdict.worse(Level.USABLE, f"{len(result.warnings)} pair(s) refused")
    return verdict


def ground_verdict(result: GroundResult) -> Verdict:
    """Plane RMS, share of points on the ground, the solver's warnings."""
    verdict = Verdict()
    grade(verdict, 1000 * result.rms_m, 4.0, 8.0, f"plane RMS {1000 * result.rms_m:.1f} mm")
    if result.inlier_fraction < 0.5:
        verdict.worse(
            Level.USABLE, f"only {100 * result.inlier_fraction:.0f} % of points on the ground"
        )
    for warning in result.warnings:
        verdict.worse(Level.USABLE, warning)
    return verdict
