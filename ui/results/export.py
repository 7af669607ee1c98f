"""Export of a reconstructed plot into one folder: the traits CSV (units in the column
names), each plant's PLY, the global cloud, the figures as PNG and a one-file HTML report
(:mod:`fieldapp.evaluate.report`). Plain functions (no Qt): the panel runs them in a worker."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

import numpy as np

from fieldapp.evaluate.figures import growth_png, map_png, trait_bars_png, trait_scatter_png
from fieldapp.evaluate.organ_files import write_organ_evaluation
from fieldapp.evaluate.organs import OrganEvaluation
from fieldapp.evaluate.report import ReportInputs, build_report
from fieldapp.evaluate.traits import TraitEvaluation, metrics_csv, pairs_csv
from fieldapp.io.durable import write_bytes_durably
from fieldapp.recon.outputs import ORGAN_COLUMNS, PlantRow, csv_text, write_outputs
from fieldapp.results.organ_tables import read_table
from ui.results.data import PlotResults

MAP_POINTS = 60_000


def export_results(
    results: PlotResults,
    folder: Path,
    evaluation: TraitEvaluation | None = None,
    growth: dict[str, dict[int, list[tuple[dt.date, float]]]] | None = None,
    calibration: dict[str, Any] | None = None,
    organ_evaluation: OrganEvaluation | None = None,
) -> list[Path]:
    """Write everything about ``results`` into ``folder``; returns the files written (with
    ``organ_evaluation``: ``organs_metrics.csv``, ``leaf_pairs.csv`` and its report section)."""
    organs = _organ_columns(results.results_dir)
    rows = [
        PlantRow(
            p.plant, p.x_m, p.y_m, p.height_cm, p.width_cm, p.points, **organs.get(p.plant, {})
        )
        for p in results.plants
    ]
    written = write_outputs(folder, rows, results.cloud, results.plant_clouds, results.report)
    leaves = results.results_dir / "leaves.csv"
    if leaves.is_file() and leaves.resolve() != (folder / "leaves.csv").resolve():
        written.append(_write(folder / "leaves.csv", leaves.read_bytes()))
    written.append(_write(folder / "traits.csv", csv_text(rows).encode("utf-8")))
    for name, png in figures(results, evaluation, growth).items():
        written.append(_write(folder / "figures" / f"{name}.png", png))
    if evaluation is not None:
        written.append(_write(folder / "accuracy.csv", metrics_csv(evaluation).encode("utf-8")))
        written.append(_write(folder / "pairs.csv", pairs_csv(evaluation).encode("utf-8")))
    if organ_evaluation is not None:
        written += write_organ_evaluation(folder, organ_evaluation)
    inputs = ReportInputs(
        calibration=calibration, evaluation=evaluation, organ_evaluation=organ_evaluation
    )
    written.append(_write(folder / "report.html", build_report(folder, inputs).encode("utf-8")))
    return written


def figures(
    results: PlotResults,
    evaluation: TraitEvaluation | None,
    growth: dict[str, dict[int, list[tuple[dt.date, float]]]] | None,
) -> dict[str, bytes]:
    """name -> PNG: the map, the trait bars, the scatters (with manual values) and growth."""
    points, colors = results.cloud.points, results.cloud.colors
    if len(points) > MAP_POINTS:
        chosen = np.random.default_rng(0).choice(len(points), MAP_POINTS, replace=False)
        points, colors = points[chosen], colors[chosen]
    labels = [(p.plant, p.x_m, p.y_m) for p in results.plants]
    out = {
        "map": map_png(points[:, :2], colors, labels),
        "traits": trait_bars_png([(p.plant, p.height_cm, p.width_cm) for p in results.plants]),
    }
    if evaluation is not None:
        for trait, agreement in evaluation.by_trait.items():
            if agreement.n:
                out[f"accuracy-{trait}"] = trait_scatter_png(
                    trait, *evaluation.values(trait), agreement
                )
    for trait, series in (growth or {}).items():
        if series:
            out[f"growth-{trait}"] = growth_png(trait, series, f"{trait} over the season")
    return out


def _organ_columns(results_dir: Path) -> dict[int, dict[str, Any]]:
    """The organ columns of the results folder's ``plants.csv`` by plant (none without
    ``leaves.csv``), so that an export keeps them."""
    if not (results_dir / "leaves.csv").is_file():
        return {}
    return {
        int(row["plant"]): {c: row.get(c) for c in ORGAN_COLUMNS}
        for row in read_table(results_dir / "plants.csv", ("plant",))
    }


def _write(path: Path, data: bytes) -> Path:
    write_bytes_durably(path, data)
    return path
