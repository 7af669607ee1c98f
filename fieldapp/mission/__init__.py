"""Capture missions (Qt-free): plan, run, pause, stop, resume, with nothing lost.

- :mod:`~fieldapp.mission.plan`: :class:`MissionPlan` (pydantic; YAML/JSON), :func:`default_plan`.
- :mod:`~fieldapp.mission.setup`: :func:`new_mission`, :func:`resume_mission` open the rig
  (:func:`fieldapp.rig.open_rig`) and the session folder (:mod:`~fieldapp.mission.folder`).
- :mod:`~fieldapp.mission.runner`: :class:`MissionRunner`, a thread with states and signals,
  running :func:`~fieldapp.mission.execute.run_mission` (the method, step by step) whose steps
  and their bounded retries are in :mod:`~fieldapp.mission.steps`.
- :mod:`~fieldapp.mission.events`: states, events, progress and the result.

The names below are imported on first use (PEP 562), so a GUI that only needs the events
(``fieldapp.mission.events``) does not load the runner, the rig and the calibration code (and
with them Open3D and SciPy) before its window is shown.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fieldapp.mission.events import (
        Fault,
        MissionProgress,
        MissionResult,
        MissionState,
        MissionWarning,
        Outcome,
        StationReached,
        ViewCaptured,
    )
    from fieldapp.mission.plan import MissionPlan, default_plan, load_plan, save_plan
    from fieldapp.mission.runner import MissionRunner
    from fieldapp.mission.setup import MissionSetup, new_mission, resume_mission

_WHERE = {
    "Fault": "events",
    "MissionProgress": "events",
    "MissionResult": "events",
    "MissionState": "events",
    "MissionWarning": "events",
    "Outcome": "events",
    "StationReached": "events",
    "ViewCaptured": "events",
    "MissionPlan": "plan",
    "default_plan": "plan",
    "load_plan": "plan",
    "save_plan": "plan",
    "MissionRunner": "runner",
    "MissionSetup": "setup",
    "new_mission": "setup",
    "resume_mission": "setup",
}

__all__ = [
    "Fault",
    "MissionPlan",
    "MissionProgress",
    "MissionResult",
    "MissionRunner",
    "MissionSetup",
    "MissionState",
    "MissionWarning",
    "Outcome",
    "StationReached",
    "ViewCaptured",
    "default_plan",
    "load_plan",
    "new_mission",
    "resume_mission",
    "save_plan",
]


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value
