"""``fieldapp evaluate traits|organs|spheres RESULTS_DIR``: the paper's two accuracy checks
and the organ traits'."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from fieldapp.errors import FieldappError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="accuracy of a reconstruction: traits against references, reference spheres",
        description="Accuracy checks of a reconstruction's output folder (see docs/EVALUATION.md).",
    )
    checks = parser.add_subparsers(dest="check", metavar="CHECK", required=True)
    traits = checks.add_parser(
        "traits",
        help="heights and widths against hand measurements or a simulator's truth",
        description="n, R2 (squared Pearson), RMSE, MAPE, mean bias and Bland-Altman limits of "
        "height and width; scatter plots with the 1:1 line.",
    )
    traits.add_argument("results", type=Path, help="the reconstruction's output folder")
    reference = traits.add_mutually_exclusive_group(required=True)
    reference.add_argument("--manual", type=Path, help="manual.csv: plant,height_cm,width_cm")
    reference.add_argument("--truth", type=Path, help="a simulator's truth.json (by position)")
    traits.add_argument(
        "--max-distance-m", type=float, default=0.15, help="--truth: pairing bound (0.15 m)"
    )
    traits.add_argument("--out", type=Path, help="folder for CSV and PNG (RESULTS/evaluation)")
    traits.set_defaults(handler=run_traits)
    organs = checks.add_parser(
        "organs",
        help="leaf count, leaf traits and stem diameter against hand measurements or a truth",
        description="Leaves paired within paired plants (by azimuth and insertion height "
        "against a truth, by leaf number against hand measurements); n, R2, RMSE, MAPE, bias "
        "and Bland-Altman limits of every leaf trait, of the leaf count, leaf area and stem "
        "diameter; leaves found but not in the reference and the reverse.",
    )
    organs.add_argument("results", type=Path, help="the reconstruction's output folder")
    organ_reference = organs.add_mutually_exclusive_group(required=True)
    organ_reference.add_argument(
        "--manual-leaves", type=Path, help="hand-measured leaves, leaves.csv's columns"
    )
    organ_reference.add_argument("--truth", type=Path, help="a simulator's truth.json")
    organs.add_argument(
        "--max-distance-m", type=float, default=0.15, help="--truth: pairing bound (0.15 m)"
    )
    organs.add_argument("--out", type=Path, help="folder for the CSV (RESULTS/evaluation)")
    organs.set_defaults(handler=run_organs)
    spheres = checks.add_parser(
        "spheres",
        help="distance of the points of reference spheres to their ideal spheres",
        description="Find each sphere in cloud.ply (RANSAC, then least squares with the nominal "
        "radius) and bin the distance of its points (0-0.2, 0.2-0.5, 0.5-0.8, 0.8-1.2, >1.2 cm). "
        "Reconstruct the sphere session without the ExG filter: "
        "FIELDAPP_RECONSTRUCTION__FILTERS__EXG_THRESHOLD=-1.",
    )
    spheres.add_argument("results", type=Path, help="the reconstruction's output folder")
    spheres.add_argument(
        "--diameters-mm", default="200,300,350,400,500,600", help="nominal diameters, mm"
    )
    spheres.add_argument("--out", type=Path, help="folder for CSV and PNG (RESULTS/evaluation)")
    spheres.set_defaults(handler=run_spheres)


def _green_only(report_path: Path) -> list[str]:
    """A warning when the reconstruction at ``report_path`` kept only green points at some
    station (plants told from the soil by colour): reference spheres, white or grey, were
    filtered out there before ``cloud.ply``, and what the sphere search finds may be a plant
    (a plot of spheres among plants, reconstructed with the defaults: a "200 mm sphere" fitted
    to leaves, 23 % of its points within 0.5 cm, the other five not found)."""
    from fieldapp.recon.exg import BY_COLOUR

    try:
        separation = json.loads(report_path.read_text()).get("plant_separation") or {}
    except (OSError, ValueError, AttributeError):
        return []  # no report (a cloud from elsewhere): nothing to say
    by_colour = sorted(
        (s for s, line in separation.items() if line == BY_COLOUR.describe()),
        key=lambda s: (len(s), s),
    )
    if not by_colour:
        return []
    return [
        f"{report_path}: station{'s' if len(by_colour) > 1 else ''} {', '.join(by_colour)} kept "
        "only green points (plants separated by colour): reference spheres that are not green "
        "were filtered out there, and a sphere found may be a plant. Reconstruct the session "
        "without the excess-green filter: FIELDAPP_RECONSTRUCTION__FILTERS__EXG_THRESHOLD=-1"
    ]


def parse_diameters(text: str) -> list[float]:
    """``"200,300"`` -> ``[200.0, 300.0]``; a :class:`FieldappError` names a bad entry."""
    values = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise FieldappError(f"--diameters-mm: {part.strip()!r} is not a number") from None
        if not 10.0 <= value <= 5000.0:
            raise FieldappError(f"--diameters-mm: {value:g} is outside 10..5000 mm")
        values.append(value)
    return values


def _fmt(value: float | None, digits: int) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def run_traits(args: argparse.Namespace) -> int:
    from fieldapp.evaluate.references import load_truth, pair_with_manual, pair_with_truth
    from fieldapp.evaluate.traits import evaluate_traits, write_trait_evaluation
    from fieldapp.results.files import read_manual_csv, read_plants_csv

    if args.max_distance_m <= 0:
        raise FieldappError("--max-distance-m must be positive")
    plants = read_plants_csv(args.results / "plants.csv")
    if args.manual is not None:
        pairing = pair_with_manual(plants, read_manual_csv(args.manual))
    else:
        pairing = pair_with_truth(plants, load_truth(args.truth).plants, args.max_distance_m)
    evaluation = evaluate_traits(pairing)
    for trait, a in evaluation.by_trait.items():
        print(
            f"{trait}: n = {a.n}, R2 = {_fmt(a.r2, 4)}, RMSE = {_fmt(a.rmse, 2)} cm, "
            f"MAPE = {_fmt(a.mape_percent, 2)} %, bias = {_fmt(a.bias, 2)} cm, "
            f"95 % limits = {_fmt(a.loa_low, 2)} .. {_fmt(a.loa_high, 2)} cm"
        )
    for warning in pairing.warnings():
        print(f"warning: {warning}")
    out = args.out or args.results / "evaluation"
    written = write_trait_evaluation(out, evaluation)
    print(f"{len(written)} files -> {out}")
    return 0


def run_organs(args: argparse.Namespace) -> int:
    from fieldapp.evaluate.organ_files import (
        evaluate_organ_references,
        summary_lines,
        write_organ_evaluation,
    )

    evaluation, warnings = evaluate_organ_references(
        args.results, args.truth, args.manual_leaves, args.max_distance_m
    )
    for warning in warnings:
        print(f"warning: {warning}")
    for line in summary_lines(evaluation):
        print(line)
    out = args.out or args.results / "evaluation"
    written = write_organ_evaluation(out, evaluation)
    print(f"{len(written)} files -> {out}")
    return 0


def run_spheres(args: argparse.Namespace) -> int:
    from fieldapp.evaluate.cloud import read_cloud
    from fieldapp.evaluate.sphere_outputs import summary_lines, write_sphere_evaluation
    from fieldapp.evaluate.spheres import find_spheres

    diameters = parse_diameters(args.diameters_mm)
    points, _ = read_cloud(args.results / "cloud.ply")
    for line in _green_only(args.results / "report.json"):
        print(f"warning: {line}", file=sys.stderr)
    fits = find_spheres(points, diameters)
    for line in summary_lines(fits):
        print(line)
    out = args.out or args.results / "evaluation"
    written = write_sphere_evaluation(out, fits)
    print(f"{len(written)} files -> {out}")
    return 0 if all(f.found for f in fits) else 1
