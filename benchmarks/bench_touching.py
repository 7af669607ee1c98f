"""The plants step on touching canopies (issue 20): accuracy per seed and its spread.

``prepare`` simulates sessions (``fieldapp simulate --stage touching`` and seedling plots, of
the default plant model or of ``--plant-model``; keep each model in its own ``--dir``),
reconstructs each up to the plants step once and pickles that step's inputs (the plot cloud,
its doubtful points and soil in the map frame, the points' mixed-pixel flags, the local ground
radius; inputs prepared before the doubtful points or the flags were kept run without them).
Any session with a ``truth.json`` may be put in ``--dir`` as ``t<N>`` or ``s<N>`` (a link to
another renderer's session): it is prepared as it is, not simulated. ``run`` then runs only
the plants step (without a grid prior) and its traits on every pickled input, and on perturbed
copies of it (a random share of the points dropped), and prints per session: plants found /
phantoms, height and width RMSE and MAPE, flagged plants, the worst plant and its width error
(matched to ``truth.json`` within 12 cm in the map frame), the plants step's CPU time, and the
spread of width RMSE over the perturbations (``--shift``: also over rigid shifts of a few mm,
which move only where the voxel grid cuts the plants):

    .venv/bin/python benchmarks/bench_touching.py prepare --dir /tmp/touching \
        --touching 0-8 --seedling 0-2 [--plant-model irregular] [--lean 20] \
        [--sensor "--color-holes --veil 3"]
    .venv/bin/python benchmarks/bench_touching.py run --dir /tmp/touching [--perturb 3] \
        [--shift 5] [--set stems.follow_leaves=false] [--only t3,t8] [--plants]

``--set`` overrides a plant setting (dotted path under ``plants``) for the run; ``--plants``
prints every plant's width error.
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

MATCH_RADIUS_M = 0.12
DROP_SHARE = 0.03


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in filter(None, text.split(",")):
        low, _, high = part.partition("-")
        out.extend(range(int(low), int(high or low) + 1))
    return out


class _Stop(Exception):
    pass


def _keeper(target: Path) -> Any:
    """A stand-in for ``stages.find_plants`` that pickles its inputs to ``target`` and stops."""

    def keep(placed: Any, settings: Any, ground_radius_m: float, grid: Any) -> Any:
        inputs = {
            "points": placed.cloud.points,
            "colors": placed.cloud.colors,
            "mixed": placed.cloud.mixed,
            "soil_m": placed.soil_m,
            "ground_radius_m": ground_radius_m,
            "doubtful_points": placed.doubtful.points,
            "doubtful_colors": placed.doubtful.colors,
            "doubtful_mixed": placed.doubtful.mixed,
        }
        target.write_bytes(pickle.dumps(inputs))
        raise _Stop

    return keep


def prepare(
    folder: Path,
    touching: list[int],
    seedling: list[int],
    plant_model: str = "distichous",
    lean: str | None = None,
    sensor: list[str] | None = None,
) -> None:
    from fieldapp.io.session import load_session
    from fieldapp.recon import stages
    from fieldapp.recon.pipeline import run_reconstruction
    from fieldapp.recon.settings import ReconstructionSettings

    runs = [(f"t{s}", s, "touching") for s in touching] + [
        (f"s{s}", s, "seedling") for s in seedling
    ]
    for name, seed, stage in runs:
        session = folder / name
        if not (session / "truth.json").exists():
            cmd = [sys.executable, "-m", "fieldapp", "simulate", "--out", str(session)]
            cmd += ["--plant-model", plant_model] + (["--lean", lean] if lean else [])
            cmd += sensor or []
            subprocess.run([*cmd, "--seed", str(seed), "--stage", stage], check=True)
        target = folder / f"{name}.pkl"
        if target.exists():
            continue
        original = stages.find_plants
        stages.find_plants = _keeper(target)
        try:
            run_reconstruction(load_session(session), ReconstructionSettings(threads=1))
        except _Stop:
            pass
        finally:
            stages.find_plants = original
        print(name, "prepared", flush=True)


def _settings(overrides: list[str]) -> Any:
    from fieldapp.recon.settings import PlantSettings

    data: dict[str, Any] = PlantSettings().model_dump()
    for item in overrides:
        path, _, value = item.partition("=")
        *parents, leaf = path.split(".")
        node = data
        for key in parents:
            node = node[key]
        node[leaf] = json.loads(value)
    return PlantSettings.model_validate(data)


def evaluate(inputs: dict[str, Any], truth_path: Path, settings: Any) -> dict[str, Any]:
    """The plants step on one input, matched to the truth."""
    from fieldapp.evaluate.metrics import agreement
    from fieldapp.evaluate.references import load_truth
    from fieldapp.recon.cloud import Cloud
    from fieldapp.recon.plants import search_plants
    from fieldapp.results.identity import match_positions

    # inputs prepared before the doubtful points, or the mixed pixels' flags, have none
    cloud = Cloud(inputs["points"], inputs["colors"], inputs.get("mixed"))
    doubtful = None
    if "doubtful_points" in inputs:
        doubtful = Cloud(
            inputs["doubtful_points"], inputs["doubtful_colors"], inputs.get("doubtful_mixed")
        )
    start = time.process_time()
    search = search_plants(
        cloud, inputs["soil_m"], settings, inputs["ground_radius_m"], None, doubtful
    )
    cpu = time.process_time() - start
    truth = load_truth(truth_path).plants
    truth_xy = np.array([t.plot_xy_m for t in truth]).reshape(-1, 2)
    plants = search.plants
    plant_xy = np.array([[p.traits.x_m, p.traits.y_m] for p in plants]).reshape(-1, 2)
    matches = match_positions(truth_xy, plant_xy, MATCH_RADIUS_M)
    rows = [
        (truth[m].name, p, 100 * p.traits.height_m, 100 * p.traits.width_m, truth[m])
        for p, m in zip(plants, matches, strict=True)
        if m is not None
    ]
    height = agreement([r[2] for r in rows], [r[4].height_cm for r in rows])
    width = agreement([r[3] for r in rows], [r[4].width_cm for r in rows])
    errors = sorted(
        ((r[3] - r[4].width_cm, r[0], r[1].ambiguous_share) for r in rows), key=lambda e: -abs(e[0])
    )
    flag = settings.stems.flag_ambiguous_share
    return {
        "found": len(rows),
        "truth": len(truth),
        "phantoms": sum(m is None for m in matches),
        "height_rmse": height.rmse,
        "height_mape": height.mape_percent,
        "width_rmse": width.rmse,
        "width_mape": width.mape_percent,
        "flagged": sum(p.ambiguous_share > flag for p in plants),
        "errors": errors,
        "cpu_s": cpu,
        "merges": search.merges,
    }


def _shifted(inputs: dict[str, Any], shift_mm: tuple[float, float, float]) -> dict[str, Any]:
    """The whole cloud and soil shifted by ``shift_mm``: nothing a plant is moves, only where
    the plants step's voxel grid cuts it."""
    shift = np.array(shift_mm) / 1000.0
    shifted = {**inputs, "points": inputs["points"] + shift, "soil_m": inputs["soil_m"] + shift}
    if "doubtful_points" in inputs:
        shifted["doubtful_points"] = inputs["doubtful_points"] + shift
    return shifted


def _perturbed(inputs: dict[str, Any], seed: int) -> dict[str, Any]:
    """A random 3 % of the points dropped (``seed`` 1, 2, ...)."""
    rng = np.random.default_rng(seed)
    keep = rng.random(len(inputs["points"])) >= DROP_SHARE
    mixed = inputs.get("mixed")
    return {
        **inputs,
        "points": inputs["points"][keep],
        "colors": inputs["colors"][keep],
        "mixed": None if mixed is None else mixed[keep],
    }


SHIFTS_MM = ((3.0, 0.0, 0.0), (0.0, 3.0, 0.0), (5.0, 5.0, 0.0), (0.0, 0.0, 3.0), (7.0, 2.0, 5.0))
"""``--shift``'s rigid shifts of the input, millimetres: under the graph's 1 cm voxels."""


def run(
    folder: Path, only: list[str], perturb: int, overrides: list[str], every: bool, shift: int = 0
) -> None:
    settings = _settings(overrides)
    names = sorted((p.stem for p in folder.glob("*.pkl")), key=lambda n: (n[0] == "s", int(n[1:])))
    names = [n for n in names if not only or n in only]
    print(
        "session found phant  h_rmse h_mape  w_rmse w_mape flag  worst            cpu_s  "
        "w_rmse perturbed (min-max of all inputs)"
    )
    for name in names:
        inputs = pickle.loads((folder / f"{name}.pkl").read_bytes())
        truth = folder / name / "truth.json"
        f = evaluate(inputs, truth, settings)
        variants = [_perturbed(inputs, s) for s in range(1, perturb + 1)]
        variants += [_shifted(inputs, mm) for mm in SHIFTS_MM[:shift]]
        spread = [evaluate(v, truth, settings)["width_rmse"] for v in variants]
        worst = f"{f['errors'][0][1]} {f['errors'][0][0]:+.1f}" if f["errors"] else "-"
        extra = ""
        if spread:
            every_input = [f["width_rmse"], *spread]
            extra = " ".join(f"{w:.2f}" for w in spread)
            extra += f" ({min(every_input):.2f}-{max(every_input):.2f})"
        print(
            f"{name:7s} {f['found']:2d}/{f['truth']:2d} {f['phantoms']:3d}  "
            f"{f['height_rmse']:6.2f} {f['height_mape']:5.2f}%  {f['width_rmse']:6.2f} "
            f"{f['width_mape']:5.2f}% {f['flagged']:3d}  {worst:15s} {f['cpu_s']:6.2f}  {extra}",
            flush=True,
        )
        if every:
            print(
                "        "
                + ", ".join(
                    f"{n} {e:+.1f}{'*' if a > settings.stems.flag_ambiguous_share else ''}"
                    for e, n, a in f["errors"]
                    if abs(e) >= 1.0
                )
            )


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("prepare")
    p.add_argument("--dir", type=Path, required=True)
    p.add_argument("--touching", type=_seeds, default=_seeds("0-8"))
    p.add_argument("--seedling", type=_seeds, default=_seeds("0-2"))
    p.add_argument("--plant-model", default="distichous")
    p.add_argument("--lean", default=None, help="simulate --lean DEG (stems leaning more)")
    p.add_argument(
        "--sensor",
        default="",
        help='more simulate options for the sensor, e.g. "--color-holes --veil 3" (one --dir each)',
    )
    r = sub.add_parser("run")
    r.add_argument("--dir", type=Path, required=True)
    r.add_argument("--only", type=lambda t: t.split(","), default=[])
    r.add_argument("--perturb", type=int, default=0)
    r.add_argument(
        "--shift", type=int, default=0, help="also run on the input shifted by N of SHIFTS_MM"
    )
    r.add_argument("--set", action="append", default=[])
    r.add_argument("--plants", action="store_true")
    args = parser.parse_args()
    if args.command == "prepare":
        prepare(
            args.dir, args.touching, args.seedling, args.plant_model, args.lean, args.sensor.split()
        )
    else:
        run(args.dir, args.only, args.perturb, args.set, args.plants, args.shift)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
