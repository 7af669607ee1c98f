"""The sphere check's outputs: ``spheres.csv`` (per sphere and overall) and histogram PNGs."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from fieldapp.evaluate.spheres import BIN_LABELS, SphereFit, bin_fractions, within_fraction
from fieldapp.io.durable import write_bytes_durably

PAPER_WITHIN_0_5_CM = 0.5526
PAPER_WITHIN_0_8_CM = 0.7688


def all_distances(fits: list[SphereFit]) -> np.ndarray:
    """Distances (M,) of the points of every sphere found."""
    return np.concatenate([f.distances_m for f in fits if f.found] or [np.zeros(0)])


def spheres_csv(fits: list[SphereFit]) -> str:
    """One row per sphere and an ``all`` row: centre, free radius, points, % per bin."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    bins = [f"percent_{label}_cm" for label in BIN_LABELS]
    writer.writerow(
        [
            "sphere_mm",
            "found",
            "x_m",
            "y_m",
            "z_m",
            "free_diameter_mm",
            "points",
            *bins,
            "percent_within_0.5_cm",
            "percent_within_0.8_cm",
        ]
    )
    rows = [(f"{f.diameter_mm:g}", f) for f in fits]
    for name, fit in rows:
        center = ["", "", ""] if fit.center_m is None else [f"{v:.4f}" for v in fit.center_m]
        free = "" if fit.free_radius_m is None else f"{2000.0 * fit.free_radius_m:.1f}"
        writer.writerow([name, int(fit.found), *center, free, *_figures(fit.distances_m)])
    writer.writerow(
        ["all", sum(f.found for f in fits), "", "", "", "", *_figures(all_distances(fits))]
    )
    return buffer.getvalue()


def _figures(distances_m: np.ndarray) -> list[str]:
    percents = [f"{100.0 * p:.2f}" for p in bin_fractions(distances_m)]
    return [
        str(len(distances_m)),
        *percents,
        f"{100.0 * within_fraction(distances_m, 0.5):.2f}",
        f"{100.0 * within_fraction(distances_m, 0.8):.2f}",
    ]


def summary_lines(fits: list[SphereFit]) -> list[str]:
    """Human-readable lines: each sphere, then the overall figures against the paper's."""
    lines = []
    for fit in fits:
        if not fit.found or fit.center_m is None:
            lines.append(f"sphere {fit.diameter_mm:g} mm: NOT FOUND ({fit.message})")
            continue
        x, y, z = fit.center_m
        lines.append(
            f"sphere {fit.diameter_mm:g} mm at ({x:.3f}, {y:.3f}, {z:.3f}) m: "
            f"{len(fit.distances_m)} points, "
            f"{100 * within_fraction(fit.distances_m, 0.5):.1f} % within 0.5 cm, "
            f"{100 * within_fraction(fit.distances_m, 0.8):.1f} % within 0.8 cm"
        )
    everything = all_distances(fits)
    lines.append(
        f"all: {len(everything)} points, {100 * within_fraction(everything, 0.5):.2f} % within "
        f"0.5 cm (paper {100 * PAPER_WITHIN_0_5_CM:.2f}), "
        f"{100 * within_fraction(everything, 0.8):.2f} % within 0.8 cm "
        f"(paper {100 * PAPER_WITHIN_0_8_CM:.2f})"
    )
    return lines


def write_sphere_evaluation(folder: Path, fits: list[SphereFit]) -> list[Path]:
    """``spheres.csv``, ``sphere_<d>mm.png`` per sphere found and ``spheres_all.png``."""
    from fieldapp.evaluate.figures import distance_histogram_png

    written = {folder / "spheres.csv": spheres_csv(fits).encode("utf-8")}
    for fit in fits:
        if fit.found:
            percents = list(100.0 * bin_fractions(fit.distances_m))
            written[folder / f"sphere_{fit.diameter_mm:g}mm.png"] = distance_histogram_png(
                f"sphere {fit.diameter_mm:g} mm ({len(fit.distances_m)} points)",
                BIN_LABELS,
                percents,
            )
    everything = all_distances(fits)
    written[folder / "spheres_all.png"] = distance_histogram_png(
        f"all spheres ({len(everything)} points)",
        BIN_LABELS,
        list(100.0 * bin_fractions(everything)),
    )
    for path, data in written.items():
        write_bytes_durably(path, data)
    return list(written)
