"""The plants step (stems, geodesic assignment, traits) from 16 to 144 plants: linear or not.

Synthetic plots of ``n x n`` maize-like plants 0.8 m apart (a stem and 5-8 arching leaves 0.4 to
0.7 m long in random directions, so neighbours' leaves cross), about 17 k points per plant, on a
soil sample of 2 cm spacing. Prints the CPU and wall time of ``search_plants`` per plot size and
per plant; run by hand on a quiet machine:

    .venv/bin/python benchmarks/bench_plants.py [--sizes 4,6,8,10,12] [--repeats 3] \
        [--no-ribbons] [--no-sheets] [--collar 0.02] [--no-leaf-ends]

``--no-ribbons``: without following the leaves of plants with ambiguous points across
contacts (``plants.stems.follow_leaves``), to see what the ribbons cost; ``--no-sheets``:
without the sheet-aware bend cost at crossings (``plants.stems.sheet_aware``), to see what it
costs; ``--collar R``: with the per-source collar of that radius
(``plants.stems.collar_radius_m``, up to 5 cm above the foot), to see what it costs;
``--no-leaf-ends``: without looking for stems that are a leaf's end come down to the soil
(``plants.stems.leaf_ends``), to see what that costs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numpy.typing import NDArray

from fieldapp.recon.cloud import Cloud
from fieldapp.recon.plants import search_plants
from fieldapp.recon.settings import PlantSettings

SPACING_M = 0.8


def synthetic_plant(rng: np.random.Generator, x: float, y: float) -> NDArray[np.float64]:
    """(N, 3) a stem of 1 cm radius and 5-8 arching ribbon leaves standing at (x, y); the
    leaves start above the 15 cm stem band and droop to 3-7 cm above the ground."""
    height = rng.uniform(0.4, 0.5)  # above the highest leaf node (0.37 m)
    angle = rng.uniform(0, 2 * np.pi, 3000)
    z = rng.uniform(0, height, 3000)
    parts = [np.column_stack([x + 0.01 * np.cos(angle), y + 0.01 * np.sin(angle), z])]
    for k in range(int(rng.integers(5, 9))):
        u = rng.uniform(0, 1, 2000)
        across = rng.uniform(-0.03, 0.03, 2000) * (1 - 0.8 * u)
        az = rng.uniform(0, 2 * np.pi)
        length, rise, node = rng.uniform(0.4, 0.7), rng.uniform(0.05, 0.2), 0.16 + 0.03 * k
        along, side = np.array([np.cos(az), np.sin(az)]), np.array([-np.sin(az), np.cos(az)])
        xy = np.array([x, y]) + (u * length)[:, None] * along + across[:, None] * side
        droop = node + rise * np.sin(np.pi * u) - 0.8 * node * u**2  # tips end 3-7 cm up
        parts.append(np.column_stack([xy, droop]))
    return np.concatenate(parts)


def plot(n: int, seed: int) -> tuple[Cloud, NDArray[np.float64]]:
    rng = np.random.default_rng(seed)
    points = np.concatenate(
        [synthetic_plant(rng, i * SPACING_M, j * SPACING_M) for i in range(n) for j in range(n)]
    )
    grid = np.arange(-0.8, n * SPACING_M + 0.8, 0.02)
    gx, gy = np.meshgrid(grid, grid)
    soil = np.column_stack([gx.ravel(), gy.ravel(), rng.normal(0, 0.002, gx.size)])
    colors = np.tile(np.array([50, 110, 25], np.uint8), (len(points), 1))
    return Cloud(points, colors), soil


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="4,6,8,10,12", help="plot sides (plants per row)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-ribbons", action="store_true", help="leaves not followed")
    parser.add_argument(
        "--no-sheets", action="store_true", help="without the sheet-aware bend cost"
    )
    parser.add_argument("--collar", type=float, default=0.0, help="collar radius (m)")
    parser.add_argument(
        "--no-leaf-ends", action="store_true", help="stems at leaves' ends not looked for"
    )
    args = parser.parse_args()
    settings = PlantSettings()
    settings.stems = settings.stems.model_copy(
        update={
            "follow_leaves": not args.no_ribbons,
            "sheet_aware": not args.no_sheets,
            "collar_radius_m": args.collar,
            "collar_height_m": 0.05,
            "leaf_ends": not args.no_leaf_ends,
        }
    )
    print("plants  points    found  cpu_s (min)  wall_s (min)  cpu ms per plant")
    for n in (int(s) for s in args.sizes.split(",")):
        cloud, soil = plot(n, args.seed)
        cpu, wall, found = [], [], 0
        for _ in range(args.repeats):
            c0, w0 = time.process_time(), time.perf_counter()
            found = len(search_plants(cloud, soil, settings, 0.15).plants)
            cpu.append(time.process_time() - c0)
            wall.append(time.perf_counter() - w0)
        print(
            f"{n * n:6d}  {len(cloud):8d}  {found:5d}  {min(cpu):11.2f}  {min(wall):12.2f}"
            f"  {1000 * min(cpu) / (n * n):16.1f}"
        )


if __name__ == "__main__":
    main()
