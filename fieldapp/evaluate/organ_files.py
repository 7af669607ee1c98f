"""Reading organ traits (``leaves.csv``, the organ columns of ``plants.csv``, hand-measured
leaves) and writing the organ evaluation (``organs_metrics.csv``, ``leaf_pairs.csv``).

A hand-measured leaves file has ``leaves.csv``'s columns (``plant_id``, ``leaf_id`` from the
bottom, then any of the traits; an empty cell is not measured): its leaves are paired with the
algorithm's by plant and leaf number.

:func:`evaluate_organ_references` is the one evaluation that the CLI (``fieldapp evaluate
organs``), the HTML report (``fieldapp report``) and the results panel run.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from fieldapp.evaluate.organs import (
    OrganEvaluation,
    PlantOrganPair,
    evaluate_organs,
    pair_plant,
)
from fieldapp.io.durable import write_bytes_durably
from fieldapp.results.organ_tables import LEAF_TRAITS, read_table

__all__ = [
    "evaluate_organ_references",
    "leaves_by_plant",
    "read_table",
    "summary_lines",
    "write_organ_evaluation",
]

MAX_DISTANCE_M = 0.15
"""Plants are paired with a truth's within this (as ``fieldapp evaluate traits``)."""


def leaves_by_plant(rows: list[dict[str, Any]]) -> dict[int, list[dict[str, Any]]]:
    """``leaves.csv`` rows grouped by ``plant_id``, each plant's from the bottom."""
    out: dict[int, list[dict[str, Any]]] = {}
    for row in rows:
        out.setdefault(int(row["plant_id"]), []).append(row)
    for leaves in out.values():
        leaves.sort(key=lambda leaf: leaf.get("leaf_id") or 0)
    return out


def evaluate_organ_references(
    results_dir: Path,
    truth: Path | None = None,
    manual_leaves: Path | None = None,
    max_distance_m: float = MAX_DISTANCE_M,
) -> tuple[OrganEvaluation, list[str]]:
    """The organ traits of ``results_dir`` (``plants.csv``, ``leaves.csv``) against a
    simulator's ``truth`` or a file of hand-measured leaves (exactly one of them), and the
    warnings (reference plants not in the results). Bad files raise
    :class:`~fieldapp.errors.FieldappError` naming the file."""
    from fieldapp.errors import FieldappError

    if (truth is None) == (manual_leaves is None):
        raise FieldappError("give either a truth.json or a file of hand-measured leaves")
    if max_distance_m <= 0:
        raise FieldappError("--max-distance-m must be positive")
    plants = {int(r["plant"]): r for r in read_table(results_dir / "plants.csv", ("plant",))}
    found = leaves_by_plant(read_table(results_dir / "leaves.csv", ("plant_id", "leaf_id")))
    if manual_leaves is not None:
        pairs, warnings = _manual_pairs(manual_leaves, plants, found)
        return evaluate_organs(pairs), warnings
    return evaluate_organs(_truth_pairs(results_dir, truth, plants, found, max_distance_m)), []


def _truth_pairs(
    results_dir: Path,
    truth_path: Path | None,
    plants: dict[int, dict[str, Any]],
    found: dict[int, list[dict[str, Any]]],
    max_distance_m: float,
) -> list[PlantOrganPair]:
    """Plants paired with the truth's by position, their leaves by where they leave the stem."""
    from fieldapp.evaluate.references import load_truth, pair_with_truth
    from fieldapp.results.files import read_plants_csv

    if truth_path is None:
        return []
    truth_plants = list(load_truth(truth_path).plants)
    by_name = {p.name: p.model_dump() for p in truth_plants}
    pairing = pair_with_truth(
        read_plants_csv(results_dir / "plants.csv"), truth_plants, max_distance_m
    )
    return [
        pair_plant(
            p.plant, p.reference, plants[p.plant], found.get(p.plant, []), by_name[p.reference]
        )
        for p in pairing.pairs
    ]


def _manual_pairs(
    path: Path, plants: dict[int, dict[str, Any]], found: dict[int, list[dict[str, Any]]]
) -> tuple[list[PlantOrganPair], list[str]]:
    """Plants paired by id with the hand-measured leaves of ``path``, leaves by number; the
    plant's leaf count is the number of leaves measured, its area their sum when all have one."""
    pairs, warnings = [], []
    manual = leaves_by_plant(read_table(path, ("plant_id", "leaf_id")))
    for plant_id, leaves in sorted(manual.items()):
        if plant_id not in plants:
            warnings.append(f"plant {plant_id} of {path} is not in plants.csv")
            continue
        areas = [leaf.get("area_cm2") for leaf in leaves]
        known = [float(a) for a in areas if a is not None]
        expected = {
            "leaf_count": len(leaves),
            "leaf_area_cm2": sum(known) if len(known) == len(areas) else None,
            "leaves": leaves,
        }
        found_leaves = found.get(plant_id, [])
        pairs.append(
            pair_plant(plant_id, str(plant_id), plants[plant_id], found_leaves, expected, True)
        )
    return pairs, warnings


def metrics_csv(evaluation: OrganEvaluation) -> str:
    """One row per trait: level (leaf, plant), n, r2, rmse, mape_percent, bias, limits."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        ["trait", "level", "n", "r2", "rmse", "mape_percent", "bias", "loa_low", "loa_high"]
    )
    for trait, level, a in evaluation.agreements():
        writer.writerow(
            [trait, level, a.n]
            + [_fmt(v) for v in (a.r2, a.rmse, a.mape_percent, a.bias, a.loa_low, a.loa_high)]
        )
    return buffer.getvalue()


def leaf_pairs_csv(evaluation: OrganEvaluation) -> str:
    """Every paired leaf: plant, reference, leaf ids, then each trait and its reference."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    columns = [c for t in LEAF_TRAITS for c in (t, f"reference_{t}")]
    writer.writerow(["plant", "reference", "leaf_id", "reference_leaf_id", *columns])
    for pair in evaluation.pairs:
        for found, expected in pair.leaf_pairs:
            values = [_fmt(v.get(t)) for t in LEAF_TRAITS for v in (found, expected)]
            writer.writerow(
                [pair.plant, pair.reference, found.get("leaf_id"), expected.get("leaf_id"), *values]
            )
    return buffer.getvalue()


def summary_lines(evaluation: OrganEvaluation) -> list[str]:
    """What the CLI prints: the leaf count, leaves extra and missed, then every trait."""
    lines = [
        f"leaf count exact on {evaluation.count_exact} of {len(evaluation.pairs)} plants; "
        f"{evaluation.extra} leaves found but not in the reference, {evaluation.missed} "
        "reference leaves not found"
    ]
    traits = list(evaluation.by_leaf_trait.items()) + list(evaluation.by_plant_trait.items())
    for trait, a in traits:
        lines.append(
            f"{trait}: n = {a.n}, R2 = {_fmt(a.r2) or 'n/a'}, RMSE = {_fmt(a.rmse) or 'n/a'}, "
            f"MAPE = {_fmt(a.mape_percent) or 'n/a'} %, bias = {_fmt(a.bias) or 'n/a'}, "
            f"95 % limits = {_fmt(a.loa_low) or 'n/a'} .. {_fmt(a.loa_high) or 'n/a'}"
        )
    return lines


def write_organ_evaluation(folder: Path, evaluation: OrganEvaluation) -> list[Path]:
    """``organs_metrics.csv`` and ``leaf_pairs.csv`` into ``folder``."""
    written = {
        folder / "organs_metrics.csv": metrics_csv(evaluation),
        folder / "leaf_pairs.csv": leaf_pairs_csv(evaluation),
    }
    for path, text in written.items():
        write_bytes_durably(path, text.encode("utf-8"))
    return list(written)


def _fmt(value: Any) -> str:
    return "" if value is None else f"{float(value):.3f}"
