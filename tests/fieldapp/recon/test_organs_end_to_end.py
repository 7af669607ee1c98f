"""Every leaf measured on a rendered, reconstructed plot (seed 0), against the simulator's
organ truth: the issue's targets, the output files and their readers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fieldapp.evaluate.cloud import read_cloud
from fieldapp.evaluate.organs import OrganEvaluation, evaluate_organs, pair_plant
from fieldapp.recon.organs import ORGAN_LEAF
from fieldapp.recon.outputs import LEAF_COLUMNS, read_labelled_ply, write_outputs
from fieldapp.recon.result import Reconstruction

from .conftest import Simulated

pytestmark = pytest.mark.slow

MATCH_RADIUS_M = 0.12


def organ_evaluation(result: Reconstruction, truth: dict) -> OrganEvaluation:
    rows = {row.plant: row for row in result.rows()}
    leaves: dict[int, list[dict]] = {}
    for leaf in result.leaf_rows():
        leaves.setdefault(leaf.plant_id, []).append(leaf.__dict__)
    pairs = []
    for plant in truth["plants"]:
        x, y = plant.get("map_x_m", plant["x_m"]), plant.get("map_y_m", plant["y_m"])  # plot coords
        distance = [np.hypot(r.x_m - x, r.y_m - y) for r in rows.values()]
        row = list(rows.values())[int(np.argmin(distance))]
        assert min(distance) < MATCH_RADIUS_M, f"{plant['name']} not found"
        pairs.append(
            pair_plant(row.plant, plant["name"], row.__dict__, leaves.get(row.plant, []), plant)
        )
    return evaluate_organs(pairs)


def test_every_leaf_is_measured_within_the_targets(
    reconstruction: Reconstruction, plot_session: Simulated
) -> None:
    """The issue's targets, met on seeds 0-4 (docs/TRAITS.md). Measured on seed 0: length RMSE
    0.86 cm, maximum width 0.15 cm, angle from the stem 3.3 degrees, no leaf extra or missed."""
    e = organ_evaluation(reconstruction, plot_session.truth)
    leaf, plant = e.by_leaf_trait, e.by_plant_trait
    assert e.count_exact >= 0.9 * len(e.pairs)
    assert e.extra <= 4 and e.missed <= 4
    assert leaf["length_cm"].rmse <= 1.0
    assert leaf["max_width_cm"].rmse <= 0.3
    assert leaf["area_cm2"].mape_percent <= 8.0
    assert plant["leaf_area_cm2"].mape_percent <= 5.0
    assert leaf["angle_from_stem_deg"].rmse <= 5.0
    assert leaf["azimuth_deg"].rmse <= 10.0
    measured = [p for p in e.pairs if p.found["stem_diameter_mm"] is not None]
    assert len(measured) >= 0.9 * len(e.pairs)
    error = [p.found["stem_diameter_mm"] - p.expected["stem_diameter_mm"] for p in measured]
    assert np.mean(np.abs(error)) <= 1.5


def test_the_files_carry_the_organs(reconstruction: Reconstruction, tmp_path: Path) -> None:
    plant_clouds = {p.id: p.cloud for p in reconstruction.plants}
    write_outputs(
        tmp_path,
        reconstruction.rows(),
        reconstruction.cloud,
        plant_clouds,
        reconstruction.report(),
        **reconstruction.output_extras(),
    )
    lines = (tmp_path / "leaves.csv").read_text().splitlines()
    assert lines[0] == ",".join(LEAF_COLUMNS)
    assert len(lines) - 1 == sum(o.leaf_count for o in reconstruction.organs.values())
    heights: dict[str, list[tuple[int, float]]] = {}
    for line in lines[1:]:
        row = dict(zip(LEAF_COLUMNS, line.split(","), strict=True))
        leaf = (int(row["leaf_id"]), float(row["insertion_height_cm"]))
        heights.setdefault(row["plant_id"], []).append(leaf)
    for leaves in heights.values():  # the spec's leaf_id "from the bottom", by the file's heights
        assert [k for k, _ in sorted(leaves, key=lambda leaf: leaf[1])] == sorted(
            k for k, _ in leaves
        )
    cloud, labels = read_labelled_ply(tmp_path / "cloud.ply")
    assert labels is not None and len(cloud) == len(reconstruction.cloud)
    assert set(np.unique(labels.plant_id)) <= {0, *plant_clouds}
    first = reconstruction.plants[0].id
    _, plant_labels = read_labelled_ply(tmp_path / "plants" / f"{first}.ply")
    assert plant_labels is not None
    leaf_points = plant_labels.organ == ORGAN_LEAF
    assert set(np.unique(plant_labels.leaf_id[leaf_points])) == set(
        range(1, reconstruction.organs[first].leaf_count + 1)
    )
    assert np.count_nonzero(labels.plant_id == first) == len(plant_clouds[first])
    points, colors = read_cloud(tmp_path / "cloud.ply")  # Open3D skips the extra properties
    np.testing.assert_allclose(points, reconstruction.cloud.points, atol=1e-6)
    assert colors is not None
