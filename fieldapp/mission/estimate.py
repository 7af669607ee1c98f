"""The time a mission has left, from what its steps have taken so far.

A mission is moves (drive to a station) and views (turn, settle, capture). The estimate is
``moves left x time per move + views left x time per view``, each time per step an
exponentially smoothed mean of the measured durations. Counting the two kinds apart keeps
the estimate steady: the old "elapsed / captures done x captures left" counted the first
drive (and any pause) into every view still to come, so it swung (17 min, then 7, then 8).

Steps are timed from :meth:`RemainingTime.begin` (called after the pause checkpoint, so a
pause is never timed) to :meth:`RemainingTime.moved` / :meth:`RemainingTime.captured`. The
run's first drive starts wherever the base happened to be (undocking, the way to the plot), so
it only stands in until the second drive is timed, which replaces it. One
step much longer than the mean so far (a retry, an incident the operator answered late) is
counted as at most ``outlier_factor`` times the mean: the estimate follows a slower pace
over a few steps rather than jumping on one.
"""

from __future__ import annotations

import time
from collections.abc import Callable

SMOOTHING = 0.2
"""Weight of the newest duration in the smoothed mean (0: never changes, 1: the last one)."""
OUTLIER_FACTOR = 2.0


class SmoothedMean:
    """Exponentially smoothed mean of durations (s); ``None`` until the first.
    ``first_stands_in``: the second duration replaces the first instead of averaging."""

    def __init__(
        self,
        smoothing: float = SMOOTHING,
        outlier_factor: float = OUTLIER_FACTOR,
        first_stands_in: bool = False,
    ) -> None:
        if not 0.0 < smoothing <= 1.0:
            raise ValueError(f"smoothing must be in (0, 1], not {smoothing}")
        self.smoothing = smoothing
        self.outlier_factor = outlier_factor
        self.first_stands_in = first_stands_in
        self.mean_s: float | None = None
        self.count = 0

    def add(self, duration_s: float) -> None:
        duration_s = max(duration_s, 0.0)
        self.count += 1
        if self.mean_s is None or (self.first_stands_in and self.count == 2):
            self.mean_s = duration_s
            return
        duration_s = (
            min(duration_s, self.outlier_factor * self.mean_s) if self.mean_s else duration_s
        )
        self.mean_s += self.smoothing * (duration_s - self.mean_s)


class RemainingTime:
    """Moves and views left, their smoothed durations, and the time left from them."""

    def __init__(
        self,
        moves: int,
        views: int,
        clock: Callable[[], float] = time.monotonic,
        smoothing: float = SMOOTHING,
    ) -> None:
        self.moves_left = moves
        self.views_left = views
        self.clock = clock
        self.per_move = SmoothedMean(smoothing, first_stands_in=True)
        self.per_view = SmoothedMean(smoothing)
        self._step_start_s: float | None = None

    def begin(self) -> None:
        """A step (a move or a view) starts now."""
        self._step_start_s = self.clock()

    def _took_s(self) -> float | None:
        start, self._step_start_s = self._step_start_s, None
        return None if start is None else self.clock() - start

    def moved(self) -> None:
        """The base reached a station."""
        self.moves_left = max(self.moves_left - 1, 0)
        took = self._took_s()
        if took is not None:
            self.per_move.add(took)

    def captured(self) -> None:
        """A view was captured and written."""
        self.views_left = max(self.views_left - 1, 0)
        took = self._took_s()
        if took is not None:
            self.per_view.add(took)

    def skipped(self, views: int) -> None:
        """A station was given up with its ``views``: neither is left to do in this run."""
        self._step_start_s = None
        self.moves_left = max(self.moves_left - 1, 0)
        self.views_left = max(self.views_left - views, 0)

    @property
    def remaining_s(self) -> float | None:
        """Seconds left; ``None`` while a kind of step still to come was never timed."""
        total = 0.0
        for left, mean in ((self.moves_left, self.per_move), (self.views_left, self.per_view)):
            if left == 0:
                continue
            if mean.mean_s is None:
                return None
            total += left * mean.mean_s
        return total
