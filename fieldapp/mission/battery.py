"""The base's battery, checked before a mission starts and at every station.

At or below the warning level the operator is told (once per station); at or below the critical
level a mission does not start, and a running one stops after the view it is capturing has been
saved, with a fault saying to charge the battery and resume. The levels are
:class:`~fieldapp.settings.BatterySettings`. A base that does not answer is not judged here: the
next drive says so.
"""

from __future__ import annotations

import logging

from devices.base import BaseClient, BaseError
from fieldapp.mission.control import MissionFault
from fieldapp.mission.events import Fault, MissionWarning
from fieldapp.settings import BatterySettings

log = logging.getLogger(__name__)

CHARGE_ADVICE = "charge or swap the base's battery, then resume the mission"


def battery_pct(base: BaseClient) -> float | None:
    """The level the base reports now; ``None`` when it does not answer."""
    try:
        return base.status().battery_pct
    except BaseError as error:
        log.info("battery not read (%s): the next step reports the base", error)
        return None


def critical_fault(level_pct: float, limits: BatterySettings, when: str) -> MissionFault:
    what = (
        f"battery at {level_pct:.0f} %, at or below the critical level "
        f"({limits.critical_pct:.0f} %) {when}"
    )
    return MissionFault(Fault("battery", what, CHARGE_ADVICE))


def check_before_start(base: BaseClient, limits: BatterySettings) -> MissionWarning | None:
    """Raises :class:`MissionFault` below the critical level; a warning below the warning one."""
    level_pct = battery_pct(base)
    if level_pct is None:
        return None
    if level_pct <= limits.critical_pct:
        raise critical_fault(level_pct, limits, "before the mission started")
    if level_pct <= limits.warn_pct:
        return MissionWarning(
            f"battery low: {level_pct:.0f} % (warning level {limits.warn_pct:.0f} %); "
            f"the mission stops at {limits.critical_pct:.0f} %"
        )
    return None


class BatteryWatch:
    """Checks the level at each station and after each view; warns once per station."""

    def __init__(self, base: BaseClient, limits: BatterySettings) -> None:
        self.base = base
        self.limits = limits
        self._warned_station: int | None = None

    def check(self, station: int, view: int | None = None) -> MissionWarning | None:
        """After arriving at ``station`` (``view`` None) or after saving ``view`` there.
        Raises :class:`MissionFault` at the critical level."""
        level_pct = battery_pct(self.base)
        if level_pct is None:
            return None
        if level_pct <= self.limits.critical_pct:
            where = f"at station {station}" if view is None else f"after s{station} v{view}"
            raise critical_fault(level_pct, self.limits, f"({where}; captures so far are saved)")
        if level_pct <= self.limits.warn_pct and self._warned_station != station:
            self._warned_station = station
            return MissionWarning(
                f"battery low: {level_pct:.0f} % at station {station} (the mission stops at "
                f"{self.limits.critical_pct:.0f} %)",
                station,
            )
        return None
