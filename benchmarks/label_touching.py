"""Which simulated plant each point of a prepared plants-step input lies on, and who takes it.

``bench_touching.py prepare`` pickles the plants step's inputs; this labels every point of
one with the simulated plant whose surface it lies on (the plot's meshes rebuilt from the
session's seed, day, stage and plant model; sampled densely over their triangles; a point is
labelled within 1.5 cm of a sample) and prints, for each variant of the plant settings, the
labelled points the geodesic assignment (``plants.assign_by_settings``, before the ribbons)
gives to another plant than their own, by pair (own -> given):

    .venv/bin/python benchmarks/label_touching.py --dir /tmp/touching --session t8 \
        [--variant ''] [--variant 'collar_radius_m=0.02,collar_height_m=0.05']

The map frame of the prepared points is not the simulator's field frame shifted by the
plot's offset alone: registration leaves it rotated by a fraction of a degree, which puts the
points 1.1 cm (median) from their surfaces and labels only 67-73 % of them within 1.5 cm. The
points are aligned to the meshes first (eight rounds of closest-point rigid fitting: the
median distance 2.8 mm at the last round, on touching seed 6 of the second model), after which
99.9 % are labelled.
"""

from __future__ import annotations

import argparse
import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

LABEL_RADIUS_M = 0.015
SUBDIVISION = 7


def _surface_samples(
    scene: Any, offset: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.intp], list[str]]:
    samples: list[NDArray[np.float64]] = []
    owner: list[NDArray[np.intp]] = []
    names: list[str] = []
    weights = [
        (i / SUBDIVISION, j / SUBDIVISION)
        for i in range(SUBDIVISION + 1)
        for j in range(SUBDIVISION + 1 - i)
    ]
    for body in scene.bodies:
        if not body.name.startswith("p"):
            continue
        v, t = body.vertices_m, body.triangles
        parts = [a * v[t[:, 0]] + b * v[t[:, 1]] + (1 - a - b) * v[t[:, 2]] for a, b in weights]
        points = np.concatenate(parts)
        samples.append(points)
        owner.append(np.full(len(points), len(names), dtype=np.intp))
        names.append(body.name)
    return np.concatenate(samples) + offset, np.concatenate(owner), names


def _aligned(points: NDArray[np.float64], tree: cKDTree, rounds: int = 8) -> NDArray[np.float64]:
    """``points`` moved rigidly onto the surfaces of ``tree`` (closest points, the nearest 70 %
    of a 1-in-20 sample each round)."""
    sample = points[::20]
    rotation, shift = np.eye(3), np.zeros(3)
    for _ in range(rounds):
        moved = sample @ rotation.T + shift
        distance, index = tree.query(moved)
        near = distance < np.percentile(distance, 70)
        a, b = moved[near], tree.data[index[near]]
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
        fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
        step = vt.T @ fix @ u.T
        rotation, shift = step @ rotation, step @ shift + cb - step @ ca
    return points @ rotation.T + shift


def labels(folder: Path, session: str) -> tuple[NDArray[np.intp], list[str]]:
    """(N,) index into the names of the plant each point lies on (-1: none within 1.5 cm)."""
    from devices.sim.scene import PlotLayout, plot_scene

    inputs = pickle.loads((folder / f"{session}.pkl").read_bytes())
    truth = json.loads((folder / session / "truth.json").read_text())
    first = truth["plants"][0]
    offset = np.array([first["map_x_m"] - first["x_m"], first["map_y_m"] - first["y_m"], 0.0])
    rig = truth["rig"]  # the plants spread over the session's grid of stations, as simulated
    scene = plot_scene(
        int(truth["seed"]),
        int(truth.get("day", 0)),
        PlotLayout.for_stations(int(rig["grid"]), float(rig["station_spacing_m"])),
        stage=truth["stage"],
        plant_model=truth.get("plant_model", "distichous"),
        max_lean_deg=truth.get("max_lean_deg"),  # simulate --lean
        leaf_width=truth.get("leaf_width", 1.0),  # simulate --leaf-width
        grounded_leaves=truth.get("grounded_leaves", 0.0),  # simulate --grounded-leaves
        late_plants=truth.get("late_plants", 0.0),  # simulate --late-plants
    )
    samples, owner, names = _surface_samples(scene, offset)
    tree = cKDTree(samples)
    points = _aligned(inputs["points"], tree)
    distance, index = tree.query(points)
    return np.where(distance < LABEL_RADIUS_M, owner[index], -1), names


def _stem_settings(variant: str) -> Any:
    from fieldapp.recon.settings import StemSettings

    values: dict[str, Any] = {}
    for item in filter(None, variant.split(",")):
        key, _, value = item.partition("=")
        values[key] = json.loads(value)
    return StemSettings(**values)


def wrong(folder: Path, session: str, variants: list[str]) -> None:
    from fieldapp.recon.plants import assign_by_settings
    from fieldapp.recon.stems import find_stems

    label, names = labels(folder, session)
    print(f"{session}: {np.mean(label >= 0):.1%} of the points labelled")
    inputs = pickle.loads((folder / f"{session}.pkl").read_bytes())
    truth = json.loads((folder / session / "truth.json").read_text())["plants"]
    truth_xy = np.array([[p["map_x_m"], p["map_y_m"]] for p in truth])
    points, soil = inputs["points"], inputs["soil_m"]
    for variant in variants:
        settings = _stem_settings(variant)
        stems, _ = find_stems(points, soil, settings, cKDTree(soil[:, :2]))
        xy = np.array([stem.xy_m for stem in stems])
        stem_names = [
            truth[int(np.argmin(np.linalg.norm(truth_xy - p, axis=1)))]["name"] for p in xy
        ]
        stem = assign_by_settings(points, xy, settings).stem
        given = np.array([stem_names[s] if s >= 0 else "-" for s in stem])
        own = np.array([names[k] if k >= 0 else "?" for k in label])
        lost = (label >= 0) & (stem >= 0) & (given != own)
        pairs: dict[tuple[str, str], int] = {}
        for o, g in zip(own[lost], given[lost], strict=True):
            pairs[(o, g)] = pairs.get((o, g), 0) + 1
        top = sorted(pairs.items(), key=lambda kv: -kv[1])[:6]
        print(
            f"  {variant or 'defaults':55s} {int(lost.sum()):6d} given to another plant: "
            + ", ".join(f"{o}->{g} {n}" for (o, g), n in top)
        )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--dir", type=Path, required=True)
    parser.add_argument("--session", required=True)
    parser.add_argument("--variant", action="append", default=None)
    args = parser.parse_args()
    wrong(args.dir, args.session, args.variant if args.variant is not None else [""])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
