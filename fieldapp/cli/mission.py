"""``fieldapp mission plan|run|resume``: capture missions from a terminal, with a progress bar.

- ``plan --out plan.yaml``: write the default plan (the paper's 3 x 3 x 8) for editing.
- ``run [--plan FILE] [--sim] [--fast] --out SESSION``: run a plan into a new session folder.
- ``resume SESSION [--fast]``: capture what a stopped, failed or killed mission is missing.

Nobody is asked in a terminal: after a lost link (the base stopped itself) or a path still
blocked after its retries the mission stops, unless ``--on-lost-link resume`` (clear the base's
stop latch and drive again, at most the plan's navigation retries) or ``--on-blocked-path skip``
(leave the station for a resume) says otherwise; the policy in force is recorded in the plan.

Ctrl-C (or SIGTERM) stops at once: the table is held and the base stopped; ``resume`` carries
on later. Exit 0 when the session is complete, 1 on a fault (what happened and what to do are
printed), 130 when stopped.
"""

from __future__ import annotations

import argparse
import logging
import signal
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from fieldapp.errors import FieldappError

if TYPE_CHECKING:
    from rich.progress import Progress, TaskID

    from fieldapp.mission import MissionResult, MissionSetup
    from fieldapp.mission.plan import MissionPlan

EXIT_FAULT = 1
EXIT_STOPPED = 130


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "mission",
        help="plan, run and resume capture missions",
        description="Drive to each station, turn the table through each view, capture and "
        "save, into a session folder that `fieldapp verify` and `fieldapp reconstruct` read.",
    )
    actions = parser.add_subparsers(dest="mission_action", metavar="ACTION", required=True)
    plan = actions.add_parser("plan", help="write the default plan (YAML or JSON) for editing")
    plan.add_argument("--out", type=Path, required=True, help="plan file (.yaml or .json)")
    plan.set_defaults(handler=run_plan)
    run = actions.add_parser("run", help="run a plan into a new session folder")
    run.add_argument("--plan", type=Path, help="plan file (default: the 3 x 3 x 8 plan)")
    run.add_argument("--sim", action="store_true", help="simulate every device")
    run.add_argument("--out", type=Path, required=True, help="the new session folder")
    _add_speed(run)
    _add_incident_policy(run)
    run.set_defaults(handler=run_mission)
    resume = actions.add_parser("resume", help="capture what a mission folder is missing")
    resume.add_argument("session", type=Path, help="the mission's session folder")
    _add_speed(resume)
    _add_incident_policy(resume)
    resume.set_defaults(handler=resume_mission)


def _add_incident_policy(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--on-lost-link",
        choices=["stop", "resume"],
        default="stop",
        help="after the base lost its link and stopped itself: stop the mission (default) or "
        "resume by itself (reset the base and drive again)",
    )
    parser.add_argument(
        "--on-blocked-path",
        choices=["stop", "skip"],
        default="stop",
        help="when a station cannot be reached after the retries: stop (default) or skip it",
    )


def _with_incident_policy(plan: MissionPlan, args: argparse.Namespace) -> MissionPlan:
    """The plan with the command line's policy: a terminal has nobody to ask."""
    from fieldapp.settings import IncidentPolicy

    policy = IncidentPolicy(lost_link=args.on_lost_link, blocked_path=args.on_blocked_path)
    return plan.model_copy(update={"incidents": policy})


def _add_speed(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--fast", action="store_true", help="simulated devices move at once (not in real time)"
    )


def run_plan(args: argparse.Namespace) -> int:
    from fieldapp.mission.plan import default_plan, save_plan
    from fieldapp.settings import load_settings

    plan = default_plan(load_settings().devices)
    try:
        save_plan(plan, args.out)
    except OSError as error:
        raise FieldappError(f"--out: cannot write {args.out}: {error.strerror}") from None
    print(f"{args.out}: {len(plan.stations)} stations x {plan.views.count} views; edit and run "
          f"`fieldapp mission run --plan {args.out} --out SESSION`")  # fmt: skip
    return 0


def run_mission(args: argparse.Namespace) -> int:
    from fieldapp.mission.plan import default_plan, load_plan
    from fieldapp.mission.setup import new_mission
    from fieldapp.settings import DeviceSettings, load_settings

    plan = load_plan(args.plan) if args.plan else default_plan(load_settings().devices)
    if args.sim:
        realtime = plan.devices.realtime_simulation
        plan = plan.model_copy(update={"devices": DeviceSettings(realtime_simulation=realtime)})
    plan = _with_incident_policy(plan, args)
    _quiet_logs(args)
    setup = _guarded(lambda: new_mission(plan, args.out, realtime=_realtime(args)), args.out)
    return _run(setup)


def resume_mission(args: argparse.Namespace) -> int:
    from fieldapp.mission.setup import resume_mission as resume

    _quiet_logs(args)
    setup = _guarded(lambda: resume(args.session, realtime=_realtime(args)), args.session)
    setup.plan = _with_incident_policy(setup.plan, args)
    return _run(setup)


def _realtime(args: argparse.Namespace) -> bool | None:
    return False if args.fast else None


def _guarded(opener: Any, folder: Path) -> MissionSetup:
    try:
        setup: MissionSetup = opener()
    except OSError as error:
        raise FieldappError(f"{folder}: cannot write {error.filename}: {error.strerror}") from None
    return setup


def _quiet_logs(args: argparse.Namespace) -> None:
    """The progress bar and the event lines tell the story; logs only for errors."""
    if not getattr(args, "verbose", False):
        logging.getLogger("fieldapp.mission").setLevel(logging.ERROR)
        logging.getLogger("fieldapp.rig").setLevel(logging.WARNING)
        logging.getLogger("devices").setLevel(logging.ERROR)


def _run(setup: MissionSetup) -> int:
    from rich.console import Console

    console = Console(stderr=True, soft_wrap=True)
    with setup:
        for device in setup.rig.devices():
            console.print(f"{device}")
        missing = setup.missing()
        console.print(f"{setup.folder}: {len(missing)} of {len(setup.plan.capture_keys())} "
                      "captures to take")  # fmt: skip
        from fieldapp.settings import load_settings

        runner = setup.runner(load_settings().battery)  # the levels the GUI checks, too
        result = _watch(runner, console)
    for line in result.lines():
        console.print(line)
    if result.complete:
        print(f"{setup.folder}: complete ({result.captured} captures)")
        return 0
    print(f"{setup.folder}: incomplete; `fieldapp mission resume {setup.folder}` carries on")
    return EXIT_FAULT if result.outcome.value == "failed" else EXIT_STOPPED


def _watch(runner: Any, console: Any) -> MissionResult:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.fields[eta]}"))  # fmt: skip
    with Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task("mission", total=len(runner.plan.capture_keys()), eta="")
        _connect(runner, progress, task)
        previous = signal.signal(signal.SIGTERM, _interrupt)
        try:
            runner.start()
            result: MissionResult | None = None
            while result is None:
                try:
                    result = runner.wait(0.2)
                except KeyboardInterrupt:
                    progress.console.print("stopping: holding the table, stopping the base")
                    runner.stop()
        finally:
            signal.signal(signal.SIGTERM, previous)
    return result


def _connect(runner: Any, progress: Progress, task: TaskID) -> None:
    def on_progress(event: Any) -> None:
        eta = "" if event.remaining_s is None else f"{_minutes(event.remaining_s)} left"
        progress.update(task, completed=event.done, description=event.step, eta=eta)

    def on_view(event: Any) -> None:
        flag = "ok" if event.quality_ok else "BELOW QUALITY"
        progress.console.print(
            f"s{event.station:02d} v{event.view} at {event.angle_deg:7.2f} deg: "
            f"fill {event.quality.fill_rate:.0%} {flag}"
        )

    runner.progress.connect(on_progress)
    runner.view_captured.connect(on_view)

    def on_station(event: Any) -> None:
        progress.console.print(
            f"station {event.station} reached: x {event.x_m:.3f} m, y {event.y_m:.3f} m, "
            f"yaw {event.yaw_deg:.1f} deg"
        )

    runner.station_reached.connect(on_station)
    runner.warning.connect(lambda e: progress.console.print(f"warning: {e.text}"))


def _minutes(seconds: float) -> str:
    minutes, secs = divmod(round(seconds), 60)
    return f"{minutes}:{secs:02d}"


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt
