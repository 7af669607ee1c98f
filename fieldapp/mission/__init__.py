"""Capture missions (Qt-free): plan, run, pause, stop, resume, with nothing lost.

- :mod:`~fieldapp.mission.plan`: :class:`MissionPlan` (pydantic; YAML/JSON), :func:`default_plan`.
- :mod:`~fieldapp.mission.setup`: :func:`new_mission`, :func:`resume_mission` open the rig
  (:func:`fieldapp.rig.open_rig`) and the session folder (:mod:`~fieldapp.mission.folder`).
- :mod:`~fieldapp.mission.runner`: :class:`MissionRunner`, a thread with states and signals,
  running :func:`~fieldapp.mission.execute.run_mission` (the method, step by step) whose steps
  and their bounded retries are in :mod:`~fieldapp.mission.steps`.
- :mod:`~fieldapp.mission.events`: states, events, progress and the result.
"""

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
