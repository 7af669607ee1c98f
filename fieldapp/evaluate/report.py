"""One self-contained HTML report of a reconstruction (images embedded as base64 PNG):
session summary, calibration used, registration quality, plant table, organs (plants and
leaves), top-down map, figures, warnings."""

from __future__ import annotations

import base64
import datetime as dt
import html
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fieldapp import __version__
from fieldapp.evaluate.metrics import Agreement
from fieldapp.evaluate.organs import UNITS, OrganEvaluation
from fieldapp.evaluate.traits import TraitEvaluation
from fieldapp.results.files import PlantRecord, read_plants_csv, read_report
from fieldapp.results.organ_tables import LEAF_TRAITS, read_table

MAP_POINTS = 60_000

STYLE = """body{font-family:sans-serif;margin:2em;max-width:60em}
table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;
text-align:right}th{background:#eee}.warn{color:#a40}img{max-width:100%}"""


@dataclass
class ReportInputs:
    """What goes into a report beyond the results folder."""

    calibration: dict[str, Any] | None = None
    session_lines: list[str] = field(default_factory=list)
    evaluation: TraitEvaluation | None = None
    organ_evaluation: OrganEvaluation | None = None
    warnings: list[str] = field(default_factory=list)


def _e(value: object) -> str:
    return html.escape(str(value))


def _table(header: list[str], rows: list[list[object]]) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _image(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f'<p><img alt="{_e(alt)}" src="data:image/png;base64,{data}"></p>'


def _number(value: Any, digits: int) -> str:
    return f"{value:.{digits}f}" if isinstance(value, int | float) else "-"


def _uncertainty(entry: dict[str, Any]) -> str:
    """A station's estimated uncertainty, ``mm / deg``."""
    return f"{_number(entry.get('uncertainty_mm'), 1)} / {_number(entry.get('uncertainty_deg'), 2)}"


def _mm(value: Any) -> float | None:
    return 1000.0 * value if isinstance(value, int | float) else None


def calibration_section(calibration: dict[str, Any] | None) -> str:
    if calibration is None:
        return "<p class=warn>The calibration used is not known (session folder not given).</p>"
    camera = calibration.get("depth_camera", {})
    rows: list[list[object]] = [
        [k, camera.get(k, "-")] for k in ("width", "height", "fx", "fy", "cx", "cy")
    ]
    step = calibration.get("view_step") or {}
    rows.append(["view step (deg)", step.get("angle_deg", "-")])
    stations = (calibration.get("stations") or {}).get("to_reference", {})
    rows.append(["stations", ", ".join(sorted(stations, key=lambda s: int(s))) or "-"])
    rows.append(["ground matrix", "given" if calibration.get("ground") else "found by RANSAC"])
    return _table(["calibration", "value"], rows)


def registration_section(report: dict[str, Any]) -> str:
    stations = report.get("stations", {})
    if not isinstance(stations, dict) or not stations:
        return "<p class=warn>report.json has no registration results.</p>"
    rows = [
        [
            station,
            "yes" if entry.get("icp_accepted") else "no",
            entry.get("verdict", "-"),
            _uncertainty(entry),
            _number(entry.get("icp_fitness"), 3),
            _number(_mm(entry.get("icp_rmse_m")), 2),
            _number(entry.get("correction_rotation_deg"), 3),
            entry.get("message", ""),
        ]
        for station, entry in stations.items()
        if isinstance(entry, dict)
    ]
    header = ["station", "ICP accepted", "verdict", "uncertainty (mm / deg)", "fitness"]
    header += ["RMSE (mm)", "correction (deg)", "note"]
    unreliable = [
        s for s, e in stations.items() if isinstance(e, dict) and e.get("verdict") == "unreliable"
    ]
    warning = (
        f"<p class=warn>Unreliable registration: station {', '.join(unreliable)}; their plants "
        "may be misplaced or drawn twice.</p>"
        if unreliable
        else ""
    )
    return warning + _table(header, rows)


def plants_section(plants: list[PlantRecord]) -> str:
    rows: list[list[object]] = [
        [
            p.plant,
            f"{p.x_m:.3f}",
            f"{p.y_m:.3f}",
            f"{p.height_cm:.1f}",
            f"{p.width_cm:.1f}",
            p.points,
        ]
        for p in plants
    ]
    return _table(["plant", "x (m)", "y (m)", "height (cm)", "width (cm)", "points"], rows)


def map_section(results_dir: Path, plants: list[PlantRecord], warnings: list[str]) -> str:
    from fieldapp.errors import FormatError
    from fieldapp.evaluate.cloud import read_cloud
    from fieldapp.evaluate.figures import map_png

    try:
        points, colors = read_cloud(results_dir / "cloud.ply")
    except FormatError as error:
        warnings.append(f"no map: {error}")
        points, colors = np.zeros((0, 3)), None
    if len(points) > MAP_POINTS:
        chosen = np.random.default_rng(0).choice(len(points), MAP_POINTS, replace=False)
        points, colors = points[chosen], None if colors is None else colors[chosen]
    labels = [(p.plant, p.x_m, p.y_m) for p in plants]
    return _image(map_png(points[:, :2], colors, labels), "top-down map")


def evaluation_section(evaluation: TraitEvaluation | None) -> str:
    if evaluation is None:
        return ""
    from fieldapp.evaluate.figures import trait_scatter_png

    rows = []
    images = []
    for trait, a in evaluation.by_trait.items():
        rows.append([trait, *_agreement_cells(a)])
        images.append(_image(trait_scatter_png(trait, *evaluation.values(trait), a), trait))
    header = ["trait", "n", "R2", "RMSE (cm)", "MAPE (%)", "bias (cm)", "95 % limits (cm)"]
    return "<h2>Accuracy against the reference</h2>" + _table(header, rows) + "".join(images)


def _agreement_cells(a: Agreement) -> list[object]:
    """n, R2, RMSE, MAPE, bias and the 95 % limits of one trait's agreement, as table cells."""
    return [
        a.n,
        _number(a.r2, 4),
        _number(a.rmse, 2),
        _number(a.mape_percent, 2),
        _number(a.bias, 2),
        f"{_number(a.loa_low, 2)} .. {_number(a.loa_high, 2)}",
    ]


def organ_evaluation_section(evaluation: OrganEvaluation | None) -> str:
    """Agreement of every organ trait with the reference (the leaf count exact on how many
    plants, leaves found but not in the reference and the reverse), a scatter per trait."""
    if evaluation is None:
        return ""
    from fieldapp.evaluate.figures import trait_scatter_png

    rows: list[list[object]] = []
    images = []
    for trait, level, a in evaluation.agreements():
        unit = UNITS[trait]
        rows.append([trait, level, unit, *_agreement_cells(a)])
        if a.n:
            images.append(
                _image(trait_scatter_png(trait, *evaluation.values(trait), a, unit), trait)
            )
    header = ["trait", "level", "unit", "n", "R2", "RMSE", "MAPE (%)", "bias", "95 % limits"]
    counts = (
        f"<p>Leaf count exact on {evaluation.count_exact} of {len(evaluation.pairs)} plants; "
        f"{evaluation.extra} leaves found but not in the reference; {evaluation.missed} "
        "reference leaves not found.</p>"
    )
    return (
        "<h2>Organ accuracy against the reference</h2>"
        + counts
        + _table(header, rows)
        + "".join(images)
    )


def organs_section(results_dir: Path) -> str:
    """The organ traits per plant and every leaf, when the folder has ``leaves.csv``."""
    if not (results_dir / "leaves.csv").is_file():
        return "<p>Organs were not measured in this run (no leaves.csv).</p>"
    plant_columns = [
        "leaf_count",
        "leaf_area_cm2",
        "stem_diameter_mm",
        "height_max_cm",
        "height_p99_cm",
        "height_whorl_cm",
    ]
    plants = read_table(results_dir / "plants.csv", ("plant",))
    plant_rows = [[row["plant"], *(_cell(row.get(c)) for c in plant_columns)] for row in plants]
    leaves = read_table(results_dir / "leaves.csv", ("plant_id", "leaf_id"))
    leaf_rows = [
        [row["plant_id"], row["leaf_id"], *(_cell(row.get(t)) for t in LEAF_TRAITS)]
        for row in leaves
    ]
    return (
        _table(["plant", *plant_columns], plant_rows)
        + f"<p>{len(leaves)} leaves (definitions: docs/TRAITS.md)</p>"
        + _table(["plant", "leaf", *LEAF_TRAITS], leaf_rows)
    )


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    return str(value) if isinstance(value, int) else f"{value:.2f}"


def provenance_section(report: dict[str, Any]) -> str:
    """Where the results came from (``report.json``'s provenance: devices, calibration,
    software, settings hash) in one visible line with the details below it, and when this
    report was written."""
    from fieldapp.provenance import details_text, summary_line

    provenance = report.get("provenance")
    document = provenance if isinstance(provenance, dict) else None
    written = dt.datetime.now().astimezone().isoformat(timespec="seconds")
    return (
        f"<p class=provenance><b>{_e(summary_line(document))}</b></p>"
        f"<pre class=provenance>{_e(details_text(document))}</pre>"
        f"<p>report written by fieldapp {_e(__version__)}, {_e(written)}</p>"
    )


def build_report(results_dir: Path, inputs: ReportInputs) -> str:
    """The HTML text of the report of ``results_dir``."""
    from fieldapp.evaluate.figures import trait_bars_png

    report = read_report(results_dir / "report.json")
    plants = read_plants_csv(results_dir / "plants.csv")
    warnings = [*(str(w) for w in report.get("warnings", []) or []), *inputs.warnings]
    summary: list[list[object]] = [
        ["session", report.get("session", "-")],
        ["results folder", str(results_dir)],
        ["plants", len(plants)],
        ["reference station", report.get("reference_station", "-")],
        *[[f"points kept: {k}", v] for k, v in (report.get("points_kept") or {}).items()],
        *[[f"time: {k} (s)", v] for k, v in (report.get("timings_s") or {}).items()],
        *[[line, ""] for line in inputs.session_lines],  # type: ignore[list-item]
    ]
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>fieldapp report {_e(report.get('session', ''))}</title>",
        f"<style>{STYLE}</style></head><body>",
        f"<h1>Reconstruction report: {_e(report.get('session', results_dir.name))}</h1>",
        provenance_section(report),
        "<h2>Session</h2>",
        _table(["", ""], summary),
        "<h2>Calibration used</h2>",
        calibration_section(inputs.calibration),
        "<h2>Registration quality</h2>",
        registration_section(report),
        "<h2>Plants</h2>",
        plants_section(plants),
        "<h2>Organs</h2>",
        organs_section(results_dir),
        "<h2>Top-down map</h2>",
        map_section(results_dir, plants, warnings),
        "<h2>Figures</h2>",
        _image(trait_bars_png([(p.plant, p.height_cm, p.width_cm) for p in plants]), "traits"),
        evaluation_section(inputs.evaluation),
        organ_evaluation_section(inputs.organ_evaluation),
        "<h2>Warnings</h2>",
        "".join(f"<p class=warn>{_e(w)}</p>" for w in warnings) or "<p>none</p>",
        f"<!-- report.json: {_e(json.dumps(report.get('format', '')))} -->",
        "</body></html>",
    ]
    return "\n".join(parts)
