"""What a mission does when the base loses its link or cannot reach a station.

The policy is part of the plan (:class:`~fieldapp.mission.plan.IncidentPolicy`, so it is
recorded in every session): ``lost_link`` is ``ask``, ``stop`` or ``resume`` and
``blocked_path`` (after the navigation retries) ``ask``, ``stop`` or ``skip``. After a lost
link the base stays stopped (its latch) until someone decides: with ``ask`` the operator is
asked through the gate's :data:`OperatorPrompt` (the GUI sets one: resume, skip the station or
stop); with no prompt (a terminal) ``ask`` means stop. Only ``resume`` recovers by itself, and
at most ``retries.navigation`` times per station.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

log = logging.getLogger(__name__)


class IncidentKind(StrEnum):
    LOST_LINK = "lost_link"
    """The base stopped itself (its watchdog) or stopped answering."""
    BLOCKED_PATH = "blocked_path"
    """Navigation gave up on the station, retries included."""


class Choice(StrEnum):
    RESUME = "resume"
    """Clear the base's stop latch and drive to the station again."""
    SKIP_STATION = "skip_station"
    """Leave this station's views for later (``resume`` captures them) and go on."""
    STOP = "stop"
    """End the mission (it can be resumed)."""


@dataclass(frozen=True)
class Incident:
    """What the operator is asked about."""

    kind: IncidentKind
    station: int
    what: str
    choices: tuple[Choice, ...] = (Choice.RESUME, Choice.SKIP_STATION, Choice.STOP)


OperatorPrompt = Callable[[Incident], Choice]
"""Asks the operator; called on the mission's thread and may block until they answer (a GUI
hands the question to its own thread and waits). A STOP meanwhile should make it return."""


class StationSkipped(Exception):
    """The station was skipped by the operator's choice or the policy; the mission goes on."""

    def __init__(self, station: int, reason: str) -> None:
        super().__init__(f"station {station} skipped: {reason}")
        self.station = station
        self.reason = reason


_AUTOMATIC = {"resume": Choice.RESUME, "skip": Choice.SKIP_STATION, "stop": Choice.STOP}


def decide(policy: str, incident: Incident, prompt: OperatorPrompt | None) -> Choice:
    """The choice for ``incident`` under ``policy`` (``ask``, ``stop``, ``resume``, ``skip``)."""
    if policy != "ask":
        return _AUTOMATIC[policy]
    if prompt is None:
        log.warning("station %d: %s; nobody to ask: stopping", incident.station, incident.what)
        return Choice.STOP
    choice = prompt(incident)
    if choice not in incident.choices:
        log.error("the operator's answer %r is not one of %s: stopping", choice, incident.choices)
        return Choice.STOP
    log.info("station %d: %s; the operator chose %s", incident.station, incident.what, choice)
    return choice
