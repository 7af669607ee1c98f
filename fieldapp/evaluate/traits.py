"""The paper's trait accuracy check: the algorithm's heights and widths against references."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

from fieldapp.evaluate.metrics import Agreement, agreement
from fieldapp.evaluate.references import Pairing, TraitPair
from fieldapp.io.durable import write_bytes_durably

TRAITS = ("height", "width")


@dataclass(frozen=True)
class TraitEvaluation:
    """Agreement for each trait (``height``, ``width``) over the pairs that have a reference
    value for it."""

    pairing: Pairing
    by_trait: dict[str, Agreement]

    def values(self, trait: str) -> tuple[list[float], list[float]]:
        """(algorithm, reference) values of ``trait`` in cm over the pairs measured."""
        return _values(self.pairing.pairs, trait)


def _values(pairs: list[TraitPair], trait: str) -> tuple[list[float], list[float]]:
    algorithm, reference = [], []
    for pair in pairs:
        value = getattr(pair, f"reference_{trait}_cm")
        if value is not None:
            algorithm.append(float(getattr(pair, f"{trait}_cm")))
            reference.append(float(value))
    return algorithm, reference


def evaluate_traits(pairing: Pairing) -> TraitEvaluation:
    """Agreement of heights and widths over ``pairing``'s pairs."""
    return TraitEvaluation(
        pairing, {trait: agreement(*_values(pairing.pairs, trait)) for trait in TRAITS}
    )


def _fmt(value: float | None, digits: int = 3) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def metrics_csv(evaluation: TraitEvaluation) -> str:
    """One row per trait: n, r2, rmse_cm, mape_percent, bias_cm, loa_low_cm, loa_high_cm."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        ["trait", "n", "r2", "rmse_cm", "mape_percent", "bias_cm", "loa_low_cm", "loa_high_cm"]
    )
    for trait, a in evaluation.by_trait.items():
        writer.writerow(
            [
                trait,
                a.n,
                _fmt(a.r2, 4),
                _fmt(a.rmse),
                _fmt(a.mape_percent, 2),
                _fmt(a.bias),
                _fmt(a.loa_low),
                _fmt(a.loa_high),
            ]
        )
    return buffer.getvalue()


def pairs_csv(evaluation: TraitEvaluation) -> str:
    """The pairs: plant, reference, algorithm and reference traits, distance (truth only)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        [
            "plant",
            "reference",
            "height_cm",
            "reference_height_cm",
            "width_cm",
            "reference_width_cm",
            "distance_m",
        ]
    )
    for p in evaluation.pairing.pairs:
        writer.writerow(
            [
                p.plant,
                p.reference,
                _fmt(p.height_cm, 2),
                _fmt(p.reference_height_cm, 2),
                _fmt(p.width_cm, 2),
                _fmt(p.reference_width_cm, 2),
                _fmt(p.distance_m, 4),
            ]
        )
    return buffer.getvalue()


def write_trait_evaluation(folder: Path, evaluation: TraitEvaluation) -> list[Path]:
    """``traits_metrics.csv``, ``traits_pairs.csv`` and the scatter PNGs into ``folder``."""
    from fieldapp.evaluate.figures import trait_scatter_png

    written = {
        folder / "traits_metrics.csv": metrics_csv(evaluation).encode("utf-8"),
        folder / "traits_pairs.csv": pairs_csv(evaluation).encode("utf-8"),
    }
    for trait, result in evaluation.by_trait.items():
        algorithm, reference = evaluation.values(trait)
        written[folder / f"{trait}_scatter.png"] = trait_scatter_png(
            trait, algorithm, reference, result
        )
    for path, data in written.items():
        write_bytes_durably(path, data)
    return list(written)
