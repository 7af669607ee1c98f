"""The outlier removal's cost on a reconstructed plot's fused cloud: statistical then radius
outlier removal each with its own tree and search (as before issue 22), against the one
k-nearest-neighbour query of :func:`fieldapp.recon.filters.remove_outliers`; both must keep
the same points.

    .venv/bin/python benchmarks/bench_outliers.py [--session DIR] [--seed N] [--repeats N]

Without ``--session`` a seed-``N`` plot is simulated into a temporary folder first (about a
minute). The plot is reconstructed once, keeping the fused cloud handed to the outlier
removal; each way then runs ``--repeats`` times with 1 and 2 threads. Best CPU (user + system,
all threads) and wall of the runs; give the machine's load with the figures.
"""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from sessions import main_on_a_session

from fieldapp.io.session import load_session
from fieldapp.recon import stages
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.filters import radius_outliers, remove_outliers, statistical_outliers
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.settings import FilterSettings, ReconstructionSettings


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def fused_cloud(session: Path) -> Cloud:
    """The cloud the reconstruction of ``session`` hands to its outlier removal."""
    fused: list[Cloud] = []

    def keeping(cloud: Cloud, settings: FilterSettings, workers: int = 1) -> object:
        fused.append(cloud)
        return remove_outliers(cloud, settings, workers)

    stages.remove_outliers = keeping  # type: ignore[assignment]
    run_reconstruction(load_session(session), ReconstructionSettings())
    stages.remove_outliers = remove_outliers
    return fused[0]


def in_turn(cloud: Cloud, settings: FilterSettings, workers: int) -> Cloud:
    kept = cloud.select(
        statistical_outliers(cloud.points, settings.sor_neighbors, settings.sor_std_ratio, workers)
    )
    return kept.select(
        radius_outliers(kept.points, settings.ror_radius_m, settings.ror_min_points, workers)
    )


def best(work: Callable[[], Cloud], repeats: int) -> tuple[float, float, Cloud]:
    runs = []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), cpu_s()
        kept = work()
        runs.append((cpu_s() - start_cpu, time.perf_counter() - start))
    cpu, wall = min(runs)
    return cpu, wall, kept


def run(session: Path, repeats: int) -> None:
    cloud, settings = fused_cloud(session), FilterSettings()
    print(f"{session}: {len(cloud)} fused points")
    for workers in (1, 2):
        cpu_a, wall_a, a = best(lambda w=workers: in_turn(cloud, settings, w), repeats)
        cpu_b, wall_b, b = best(lambda w=workers: remove_outliers(cloud, settings, w)[0], repeats)
        same = np.array_equal(a.points, b.points)
        print(
            f"  {workers} thread(s): SOR then ROR {cpu_a:.3f} s CPU {wall_a:.3f} s wall; "
            f"one query {cpu_b:.3f} s CPU {wall_b:.3f} s wall; same points kept: {same}"
        )


def main() -> None:
    main_on_a_session(__doc__.splitlines()[0], run)


if __name__ == "__main__":
    main()
