"""Reading organ traits (``leaves.csv``, the organ columns of ``plants.csv``, hand-measured
leaves) and writing the organ evaluation (``organs_metrics.csv``, ``leaf_pairs.csv``).

A hand-measured leaves file has ``leaves.csv``'s columns (``plant_id``, ``leaf_id`` from the
bottom, then any of the traits; an empty cell is not measured): its leaves are paired with the
algorithm's by plant and leaf number.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from fieldapp.evaluate.organs import LEAF_TRAITS, PLANT_TRAITS, OrganEvaluation
from fieldapp.io.durable import write_bytes_durably
from fieldapp.results.organ_tables import read_table

__all__ = ["leaves_by_plant", "read_table", "summary_lines", "write_organ_evaluation"]


def leaves_by_plant(rows: list[dict[str, Any]]) -> dict[int, list[dict[str, Any]]]:
    """``leaves.csv`` rows grouped by ``plant_id``, each plant's from the bottom."""
    out: dict[int, list[dict[str, Any]]] = {}
    for row in rows:
        out.setdefault(int(row["plant_id"]), []).append(row)
    for leaves in out.values():
        leaves.sort(key=lambda leaf: leaf.get("leaf_id") or 0)
    return out


def metrics_csv(evaluation: OrganEvaluation) -> str:
    """One row per trait: level (leaf, plant), n, r2, rmse, mape_percent, bias, limits."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        ["trait", "level", "n", "r2", "rmse", "mape_percent", "bias", "loa_low", "loa_high"]
    )
    rows = [(t, "leaf", evaluation.by_leaf_trait[t]) for t in LEAF_TRAITS]
    rows += [(t, "plant", evaluation.by_plant_trait[t]) for t in PLANT_TRAITS]
    for trait, level, a in rows:
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
