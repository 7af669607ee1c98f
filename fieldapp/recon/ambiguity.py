"""Pairs of stations whose overlap fits in more than one place, and what the graph does with them.

On smooth relief (bare soil: clods of a few mm over waves of 6-20 cm) GICP from the coarse
poses can settle a wavelength away from the truth, and such a false placement fits as well as
the true one, often better (bare soil seed 1, stations 4, 5, 7, 8: three of six pairs 127-198
mm off with fitness 0.68-0.79 against 0.64-0.72 at the truth). Several pairs that slid the
same way agree with each other and outvote the right ones, and the plot ends silently wrong.

So each usable pair that holds its horizontal position weakly (:func:`weakly_constrained`:
bare soil, not a pair sharing plants or spheres) is probed (:func:`probe`): GICP at the finest
reach is started from its fit shifted by ``PROBE_SIGMAS`` of the pair's relative arrival
error, either way along both horizontal axes. At a true minimum every probe comes back (within
the edge tolerance); a probe that settles elsewhere with a usable fit marks the pair
*ambiguous*. An ambiguous pair gives the graph no weight at first: it is left out of the first
solution. Where that solution places the pair's stations closely enough that at most one of
the pair's known minima lies within its reach (:func:`settled`), the pair is registered again
from the solution (the plot's consistency chooses its minimum) and enters the final graph like
any other; otherwise it stays out, and its stations, held by their other pairs and priors,
get the uncertainty that follows and, when not refined, the reason (:func:`notes`): never
silently wrong.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, invert, make_transform, transform_points
from fieldapp.recon import guards, pairwise, posegraph, se3
from fieldapp.recon.pairwise import Overlap, PairFit, score
from fieldapp.recon.settings import RegistrationSettings

PROBE_SIGMAS = 2.0
"""How far each probe starts from the pair's fit, in standard deviations of the two stations'
relative arrival error per horizontal axis (8.5 cm at the default 3 cm): beyond a clod's
half-wavelength, inside the reach of an arrival error the settings expect."""

WEAK_HORIZONTAL = 0.1
"""A pair is probed when its fit holds the horizontal position this much less than the height
(square root of the ratio of the weakest horizontal information to the vertical one: about
the mean horizontal share of the overlap's normals). Bare soil gives 0.04-0.05; pairs that
share plants or spheres 0.2-0.3 and are never probed."""

PROBE_THINNING = 2.0
"""The probes' points are thinned to this many times the finest GICP size (their reach stays
the finest size's): a probe only has to find where a minimum is, not refine it."""


@dataclass(frozen=True)
class Ambiguity:
    """Pair ``a``-``b`` (index ``k`` into the fits) also fits at ``alternatives`` (``T_a_b``
    each); ``spread_m`` / ``_deg``: the farthest of them from the pair's fit, ``nearest_m``
    the nearest (at b's ground centre)."""

    k: int
    a: int
    b: int
    alternatives: tuple[Matrix4, ...]
    spread_m: float
    spread_deg: float
    nearest_m: float
    T_a_b: Matrix4

    @property
    def fits(self) -> tuple[Matrix4, ...]:
        """The pair's own fit and the alternatives."""
        return (self.T_a_b, *self.alternatives)


ProbeJob = tuple[int, Overlap, PairFit, Matrix4, RegistrationSettings]
"""One pair's probe as plain data: ``(k, overlap, fit, b's node, settings)``."""

Mapper = Callable[
    [Callable[[ProbeJob], "Ambiguity | None"], list[ProbeJob]], Iterator["Ambiguity | None"]
]
"""``map`` or a pool's ``map``: runs the probes of each pair, results in order (the function
and the jobs pickle, so a worker process can run them)."""


def probe_starts_m(settings: RegistrationSettings) -> list[Matrix4]:
    """(4,) shifts of b's placement, field axes: +-x and +-y by ``PROBE_SIGMAS`` of the pair's
    relative arrival error per axis (both stations' errors)."""
    shift_m = PROBE_SIGMAS * np.sqrt(2.0) * settings.arrival_sigma_m
    steps = [(shift_m, 0.0), (-shift_m, 0.0), (0.0, shift_m), (0.0, -shift_m)]
    return [make_transform(np.eye(3), np.array([dx, dy, 0.0])) for dx, dy in steps]


def probe_job(job: ProbeJob) -> Ambiguity | None:
    """:func:`probe` of one job (module level, so a worker process can run it)."""
    return probe(*job)


def probe(
    k: int,
    overlap: Overlap,
    fit: PairFit,
    node_b: Matrix4,
    settings: RegistrationSettings,
) -> Ambiguity | None:
    """The other minima of pair ``k`` found from the shifted starts (each once), or ``None``
    when every probe comes back to its fit (within the edge tolerance, measured at b's ground
    centre ``node_b``) or settles where the fit is unusable. Each probe is GICP with the finest
    size's reach, as a pair registered again from a guess (:func:`pairwise.icp`), on points
    thinned to ``PROBE_THINNING`` times that size, prepared once for the four probes."""
    voxel_m = settings.voxel_sizes_m[-1]
    target, tree = pairwise.thinned(overlap.points_a_m, PROBE_THINNING * voxel_m)
    source, _ = pairwise.thinned(overlap.points_b_m, PROBE_THINNING * voxel_m)
    alternatives: list[Matrix4] = []
    spread, nearest_m = (0.0, 0.0), np.inf
    for shift in probe_starts_m(settings):
        T_a_b, converged = pairwise.gicp(target, source, tree, shift @ fit.T_a_b, settings, voxel_m)
        if not all(_distinct(T, T_a_b, node_b, settings) for T in (fit.T_a_b, *alternatives)):
            continue  # back to the fit, or to a minimum already found
        fitness, _ = score(
            overlap.points_a_m,
            transform_points(T_a_b, overlap.points_b_m),
            settings.max_correspondence_m,
        )
        if converged and fitness >= settings.min_fitness:
            alternatives.append(T_a_b)
            apart = _apart(fit.T_a_b, T_a_b, node_b)
            spread = (max(spread[0], apart[0]), max(spread[1], apart[1]))
            nearest_m = min(nearest_m, apart[0])
    if not alternatives:
        return None
    return Ambiguity(k, fit.a, fit.b, tuple(alternatives), *spread, float(nearest_m), fit.T_a_b)


def ambiguous_pairs(
    overlaps: list[Overlap],
    fits: list[PairFit],
    candidates: list[int],
    nodes: dict[int, Matrix4],
    settings: RegistrationSettings,
    mapper: Mapper = map,
) -> Generator[tuple[float, str], None, dict[int, Ambiguity]]:
    """Probe each fit of ``candidates`` (indices into ``fits``) that is weakly constrained
    (:func:`weakly_constrained`); yields (1.0, message) per pair probed, so the registration
    can be followed and closed meanwhile, and returns the ambiguous ones by index."""

    weak = [k for k in candidates if weakly_constrained(fits[k].information)]
    jobs = [(k, overlaps[k], fits[k], nodes[fits[k].b], settings) for k in weak]
    found: dict[int, Ambiguity] = {}
    for k, result in zip(weak, mapper(probe_job, jobs), strict=True):
        if result is not None:
            found[k] = result
        yield 1.0, f"stations {fits[k].a}-{fits[k].b} probed for a second minimum"
    return found


def weakly_constrained(information: NDArray[np.float64]) -> bool:
    """Whether a pair's (6, 6) information holds its horizontal position less than
    ``WEAK_HORIZONTAL`` times its height (both as square roots of the information)."""
    horizontal = float(np.linalg.eigvalsh(information[3:5, 3:5])[0])
    vertical = float(information[5, 5])
    return vertical <= 0.0 or horizontal < WEAK_HORIZONTAL**2 * vertical


def settled(
    ambiguities: dict[int, Ambiguity],
    solution: posegraph.Solution,
    nodes: dict[int, Matrix4],
    settings: RegistrationSettings,
) -> dict[int, Matrix4]:
    """The ambiguous pairs whose minimum the ``solution`` (solved without them) chooses, each
    with the pair's ``T_a_b`` in that solution (its guess). The solution places b relative to
    a within ``reach_m``: ``guard_sigmas`` standard deviations (the two stations' relative to
    the reference in quadrature, their turns as the shift they make halfway between them,
    where the overlap lies). When at most one of the pair's fits (its own and the probes')
    lies within that reach of the guess, the truth is nearer the guess than any other
    known minimum: registered again from the guess, the pair settles in the minimum the
    plot agrees with."""
    sigmas = {s: guards.sigma_m_deg(c) for s, c in solution.covariance.items()}
    chosen = {}
    for k, found in sorted(ambiguities.items()):
        if found.a not in sigmas or found.b not in sigmas:
            continue  # a fixed station: the solution does not place it
        (a_m, a_deg), (b_m, b_deg) = sigmas[found.a], sigmas[found.b]
        lever_m = float(np.linalg.norm(nodes[found.b][:3, 3] - nodes[found.a][:3, 3])) / 2
        a_turn_m, b_turn_m = lever_m * np.radians(a_deg), lever_m * np.radians(b_deg)
        reach_m = settings.guard_sigmas * float(np.linalg.norm([a_m, b_m, a_turn_m, b_turn_m]))
        correction = {s: solution.T_field_node[s] @ invert(nodes[s]) for s in (found.a, found.b)}
        guess = invert(correction[found.a]) @ correction[found.b]
        near = [T for T in found.fits if _apart(guess, T, nodes[found.b])[0] <= reach_m]
        if len(near) <= 1:
            chosen[k] = guess
    return chosen


def _distinct(
    T_a_b: Matrix4, other_a_b: Matrix4, node_b: Matrix4, settings: RegistrationSettings
) -> bool:
    """Whether two placements of b are different minima: beyond the edge tolerance."""
    apart_m, apart_deg = _apart(T_a_b, other_a_b, node_b)
    return apart_m > settings.edge_tolerance_m or apart_deg > settings.edge_tolerance_deg


def _apart(T_a_b: Matrix4, other_a_b: Matrix4, node_b: Matrix4) -> tuple[float, float]:
    """(m, deg) between two placements of b, at its ground centre ``node_b``."""
    return posegraph.disagreement(se3.log(invert(node_b) @ invert(T_a_b) @ other_a_b @ node_b))


def explain(ambiguity: Ambiguity) -> str:
    """Why the pair was left out, for the station's message."""
    return (
        f"pair {ambiguity.a}-{ambiguity.b} fits as well {1000 * ambiguity.spread_m:.0f} mm / "
        f"{ambiguity.spread_deg:.2f} deg away and the plot cannot choose"
    )


def notes(left_out: Iterable[Ambiguity]) -> dict[int, str]:
    """For each station of a pair left out, why (every such pair of it, in pair order)."""
    reasons: dict[int, list[str]] = {}
    for ambiguity in left_out:
        for station in (ambiguity.a, ambiguity.b):
            reasons.setdefault(station, []).append(explain(ambiguity))
    return {station: "; ".join(texts) for station, texts in sorted(reasons.items())}
