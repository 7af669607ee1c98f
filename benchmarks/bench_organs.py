"""The organ step's cost: CPU time of :func:`measure_organs` for the plants of a reconstructed
plot, and how it grows with the number of plants.

    .venv/bin/python benchmarks/bench_organs.py [--session DIR] [--seed N] [--repeats N]

Without ``--session`` a seed-``N`` plot is simulated into a temporary folder first (about a
minute). The plot is reconstructed once; then the organ step runs ``--repeats`` times over its
16 plants, and over 4, 8, 32 and 64 plants (the plot's plants repeated) to show the cost is
linear in plants. Target: at most 1 s CPU for 16 plants. CPU time is this process's (user +
system, all threads); on a loaded machine it still grows a little (caches, hyperthreads).
"""

from __future__ import annotations

import resource
import statistics
from pathlib import Path

from sessions import main_on_a_session

from fieldapp.io.session import load_session
from fieldapp.recon.organ_traits import foot_m, measure_organs
from fieldapp.recon.pipeline import run_reconstruction
from fieldapp.recon.plants import Plant
from fieldapp.recon.settings import ReconstructionSettings


def cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def organ_cpu_s(plants: list[Plant]) -> float:
    start = cpu_s()
    for plant in plants:
        measure_organs(plant.cloud.points, foot_m(plant.traits))
    return cpu_s() - start


def run(session: Path, repeats: int) -> None:
    result = run_reconstruction(load_session(session), ReconstructionSettings())
    plants = result.plants
    points = sum(len(p.cloud) for p in plants)
    print(f"{session}: {len(plants)} plants, {points} points")
    times = [organ_cpu_s(plants) for _ in range(repeats)]
    print(
        f"  organ step, {len(plants)} plants: median {statistics.median(times):.3f} s CPU "
        f"(runs: {', '.join(f'{t:.3f}' for t in times)})"
    )
    for count in (4, 8, 16, 32, 64):
        chosen = [plants[i % len(plants)] for i in range(count)]
        cost = statistics.median(organ_cpu_s(chosen) for _ in range(max(1, repeats // 2)))
        print(f"  {count:3d} plants: {cost:.3f} s CPU, {1000 * cost / count:.1f} ms per plant")


def main() -> None:
    main_on_a_session(__doc__.splitlines()[0], run)


if __name__ == "__main__":
    main()
