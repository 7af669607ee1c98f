"""``fieldapp verify``: a complete check of a session folder against the spec."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from fieldapp.errors import FormatError, Problem
from fieldapp.io.images import ImageError, read_color, read_depth_units, read_ir
from fieldapp.io.session import Capture, Session, load_session


@dataclass
class VerifyReport:
    """What ``verify`` found: the problems (none means usable) and a summary of the content."""

    folder: Path
    problems: list[Problem] = field(default_factory=list)
    session: Session | None = None
    views_by_station: dict[int, list[int]] = field(default_factory=dict)
    missing: list[tuple[int, int]] = field(default_factory=list)
    uncalibrated: list[int] = field(default_factory=list)
    """Captured stations without ``stations.to_reference`` in calibration.json: the session is
    valid, but a reconstruction leaves them out."""

    @property
    def usable(self) -> bool:
        return self.session is not None and not self.problems

    def summary_lines(self) -> list[str]:
        if self.session is None:
            return []
        lines = [
            f"session {self.session.id}: {len(self.session.captures)} captures, "
            f"{len(self.views_by_station)} stations"
        ]
        if not self.session.captures:
            lines.append("no captures yet (an interrupted mission?): nothing to reconstruct")
        for station, views in sorted(self.views_by_station.items()):
            lines.append(f"  station {station}: views {', '.join(map(str, views))}")
        if self.missing:
            listed = ", ".join(f"s{s} v{v}" for s, v in self.missing)
            lines.append(f"missing captures ({len(self.missing)}): {listed}")
        else:
            lines.append("no missing captures")
        if self.uncalibrated:
            listed = ", ".join(map(str, self.uncalibrated))
            lines.append(
                f"warning: calibration.json: stations.to_reference has no entry for station(s) "
                f"{listed}: a reconstruction leaves them out"
            )
        return lines


def capture_file_problems(session: Session, capture: Capture) -> list[Problem]:
    """Check each of a capture's files: a regular file, its recorded checksum, its header's
    kind and size (before decoding), then decodable. One problem per bad file."""
    readers = {"depth": read_depth_units, "color": read_color, "ir": read_ir}
    problems = []
    for name, relative in capture.files().items():
        try:
            readers[name](session.path_of(relative), name, session.expected(capture, name))
        except ImageError as error:
            problems.append(error.problem)
    return problems


def verify_session(folder: Path) -> VerifyReport:
    """Check ``folder`` completely: documents, calibration, every referenced image."""
    report = VerifyReport(folder)
    try:
        session = load_session(folder, allow_empty=True)  # the spec: may lack captures
    except FormatError as error:
        report.problems = error.problems
        return report
    report.session = session
    views: dict[int, list[int]] = defaultdict(list)
    for capture in session.captures:
        views[capture.station].append(capture.view)
        report.problems += capture_file_problems(session, capture)
    report.views_by_station = {s: sorted(v) for s, v in views.items()}
    report.missing = session.missing()
    stations = session.calibration.stations
    if stations is not None:  # without any, the session is for other uses than a plot
        report.uncalibrated = sorted(set(views) - set(stations.to_reference))
    return report
