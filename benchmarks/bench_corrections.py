"""Manual corrections on a real results folder, timed with the load: merge the two nearest
plants, split them again by their stems, delete one, renumber one, undo each; and how well the
split gives each plant back its own points. Run by hand on a reconstruction's folder:
``.venv/bin/python benchmarks/bench_corrections.py RESULTS_DIR`` (it works on a copy).
"""

from __future__ import annotations

import argparse
import functools
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from fieldapp.recon.outputs import read_labelled_ply
from fieldapp.results.corrected import add_correction, undo_correction
from fieldapp.results.corrections import Corrections, Delete, Merge, PlantRef, Relabel, Split
from fieldapp.results.files import read_plants_csv


def _refs(folder: Path) -> tuple[dict[int, PlantRef], dict[int, np.ndarray]]:
    cloud, labels = read_labelled_ply(folder / "cloud.ply")
    assert labels is not None
    refs, members = {}, {}
    for plant in np.unique(labels.plant_id[labels.plant_id > 0]):
        index = np.flatnonzero(labels.plant_id == plant)
        x, y = cloud.points[index, :2].mean(axis=0)
        refs[int(plant)] = PlantRef(plant=int(plant), xy_m=(float(x), float(y)))
        members[int(plant)] = cloud.points[index]
    return refs, members


def _timed(name: str, call):  # type: ignore[no-untyped-def]
    wall, cpu = time.perf_counter(), time.process_time()
    result = call()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"{name:<34} {wall:6.2f} s wall {cpu:6.2f} s CPU")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("results", type=Path)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(shutil.copytree(args.results, Path(tmp) / "results"))
        rows = {r.plant: r for r in read_plants_csv(folder / "plants.csv")}
        refs, members = _refs(folder)
        xy = np.array([[rows[p].x_m, rows[p].y_m] for p in sorted(rows)])
        distance = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy)) * 1e9
        i, j = np.unravel_index(int(np.argmin(distance)), distance.shape)
        a, b = sorted(rows)[i], sorted(rows)[j]
        print(
            f"{len(rows)} plants, {sum(len(m) for m in members.values())} plant points; "
            f"merging {a} and {b}, {100 * distance[i, j]:.0f} cm apart"
        )
        merged = _timed(
            "merge",
            lambda: add_correction(
                folder, Corrections(), Merge(plants=[refs[a], refs[b]], into=min(a, b))
            ),
        )
        new_refs, _ = _refs(folder)
        stems = [(rows[a].x_m, rows[a].y_m), (rows[b].x_m, rows[b].y_m)]
        split = Split(plant=new_refs[min(a, b)], stems_xy_m=stems, into=[min(a, b), max(rows) + 1])
        done = _timed(
            "split by the two stems", lambda: add_correction(folder, merged.corrections, split)
        )
        _, back = _refs(folder)
        for plant, other in ((min(a, b), a), (max(rows) + 1, b)):
            mine = {tuple(p) for p in np.round(members[other], 6)}
            got = {tuple(p) for p in np.round(back[plant], 6)}
            print(
                f"  plant {other}: {100 * len(mine & got) / len(mine):.1f} % of its points back, "
                f"{len(got - mine)} of another"
            )
        done = _timed(
            "delete",
            lambda: add_correction(
                folder, done.corrections, Delete(plant=_refs(folder)[0][max(rows) + 1])
            ),
        )
        done = _timed(
            "renumber",
            lambda: add_correction(
                folder, done.corrections, Relabel(plant=_refs(folder)[0][min(a, b)], into=999)
            ),
        )
        for k in range(4):
            done = _timed(
                f"undo ({4 - k} operations left)",
                functools.partial(undo_correction, folder, done.corrections),
            )


if __name__ == "__main__":
    main()
