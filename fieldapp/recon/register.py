"""Global registration: one pose graph of all the plot's stations.

Coarse poses come from the station pre-calibration (after levelling). Every pair of stations
whose views overlap is registered on all the geometry the two share (:mod:`pairwise`); these
edges and a prior per station (its coarse pose relative to the reference, weighted by the
expected arrival error, :mod:`guards`) make one pose graph, solved robustly with loop closure
(:mod:`posegraph`): edges that disagree with the rest are dropped. A station's correction is
kept only when it is plausible for its expected error and makes its overlaps agree better than
the coarse pose; otherwise the station is fixed at its coarse pose and the graph solved again.
Every station gets a verdict (refined, coarse kept, unreliable) and an estimated uncertainty.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Generator, Iterable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from devices.geometry import Matrix4, invert, make_transform, transform_points
from fieldapp.recon import ambiguity, guards, posegraph, se3
from fieldapp.recon.forkmap import ForkedMap
from fieldapp.recon.pairwise import Overlap, PairFit, find_overlaps, register_overlap
from fieldapp.recon.settings import RegistrationSettings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StationRegistration:
    """How one station was placed. ``T_correction`` maps its coarse field placement onto the
    final one (identity when the coarse pose is kept). ``fitness`` and ``rmse_m``: the mean
    of its kept edges; ``uncertainty_m``/``_deg``: estimated standard deviation of its pose
    relative to the reference station; ``limit_m``/``_deg``: the largest correction its
    expected arrival error allows (``guard_sigmas`` standard deviations)."""

    station: int
    T_field_station: Matrix4
    T_correction: Matrix4
    neighbours: list[int] = field(default_factory=list)
    fitness: float | None = None
    rmse_m: float | None = None
    accepted: bool = False
    message: str = ""
    verdict: str = guards.COARSE_KEPT
    uncertainty_m: float | None = None
    uncertainty_deg: float | None = None
    limit_m: float | None = None
    limit_deg: float | None = None
    misfit: bool = False
    """Kept coarse because its correction did not make its overlaps agree better."""


def beyond_arrival(registration: StationRegistration) -> bool:
    """Whether the station may have been left coarse or unreliable by an arrival error larger
    than the settings expect: its correction, or every pair it has, lay beyond it, or too few
    pairs were kept to place it. Not a :attr:`~StationRegistration.misfit`: a fit in the wrong
    place, which a wider prior would not mend."""
    return registration.verdict in (guards.COARSE_KEPT, guards.UNRELIABLE) and not (
        registration.misfit
    )


def ground_centre_m(
    T_field_station: Matrix4, axis_point_station_m: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Where the station's turntable axis meets the ground (z = 0), field frame (3,)."""
    centre: NDArray[np.float64] = transform_points(T_field_station, axis_point_station_m[None])[0]
    centre[2] = 0.0
    return centre


RegistrationSteps = Generator[tuple[float, str], None, dict[int, StationRegistration]]


def register_stations(
    points_station_m: dict[int, NDArray[np.float64]],
    T_field_station_coarse: dict[int, Matrix4],
    axis_point_station_m: NDArray[np.float64],
    reference: int,
    settings: RegistrationSettings,
    threads: int = 1,
    known: PairFits | None = None,
) -> RegistrationSteps:
    """Place every station; yields (fraction done, message) per registered overlap and returns
    the registrations by station.

    ``points_station_m``: per station, the (N, 3) points to register, in its view-0 frame.
    ``axis_point_station_m``: (3,) a point of the turntable axis in view-0 frame.
    ``known``: the pair fits of earlier registrations of these same points (:class:`PairFits`),
    taken from there where a pair starts as it did then, and added to.
    """
    nodes = {
        s: make_transform(np.eye(3), ground_centre_m(T, axis_point_station_m))
        for s, T in T_field_station_coarse.items()
    }
    if not settings.enabled:
        return _coarse_only(T_field_station_coarse, nodes, reference, settings)
    field_points = {
        s: transform_points(T_field_station_coarse[s], points_station_m[s])
        for s in sorted(T_field_station_coarse)
    }
    overlaps = find_overlaps(field_points, settings)
    fits: list[PairFit] = []
    # pairs shared by this process and a forked worker (GICP holds the GIL: threads would
    # take turns); the same fits wherever a pair runs (forkmap's docstring)
    with ForkedMap(threads) as runner:
        each = runner.worker_threads
        # closing this generator closes map's iterator, which drops the pairs not started
        for fit in _fits(
            runner.map,
            [(o, nodes[o.b][:3, 3], settings, None, each) for o in overlaps],
            _pair_costs(overlaps),
            T_field_station_coarse,
            known,
        ):
            fits.append(fit)
            yield len(fits) / len(overlaps), f"stations {fit.a}-{fit.b} registered"
        doubtful = yield from ambiguity.ambiguous_pairs(
            overlaps,
            fits,
            _usable_fits(_edges(nodes, fits, reference, settings)[0], fits, nodes, settings),
            nodes,
            settings,
            runner.map,
        )
        first = _first_solution(nodes, fits, reference, settings, set(doubtful))
        guesses = _consensus_guesses(nodes, fits, first, settings)
        guesses |= ambiguity.settled(doubtful, first[1], nodes, settings)
        again = _fits(
            runner.map,
            [
                (overlaps[k], nodes[overlaps[k].b][:3, 3], settings, guesses[k], each)
                for k in sorted(guesses)
            ],
            None,
            T_field_station_coarse,
            known,
        )
        for k, fit in zip(sorted(guesses), again, strict=True):
            fits[k] = fit
            yield 1.0, f"stations {fit.a}-{fit.b} registered again from the plot's solution"
        left_out = [doubtful[k] for k in sorted(set(doubtful) - set(guesses))]
        # the guards' overlap checks, a pair at a time, on both processes (forked only: on
        # threads the trees' builds would take turns on the GIL)
        registrations = _solve_plot(
            nodes,
            overlaps,
            fits,
            reference,
            settings,
            T_field_station_coarse,
            None if guesses else first[1],
            {found.k for found in left_out},
            runner.map if runner.forked else None,
        )
    for station, note in ambiguity.notes(left_out).items():  # never silently wrong
        if registrations[station].verdict in (guards.COARSE_KEPT, guards.UNRELIABLE):
            message = f"{registrations[station].message}; {note}"
            registrations[station] = replace(registrations[station], message=message)
    return registrations


PairJob = tuple[Overlap, NDArray[np.float64], RegistrationSettings, Matrix4 | None, int]
"""One pair to register as plain data: ``(overlap, b's centre, settings, guess, threads)``."""


class PairFits:
    """The pair fits of one set of station points (``register_stations``' ``points_station_m``),
    by what decides each: the two stations' starting poses (which make the overlap's points
    and b's centre), the guess it starts from (none: the whole ladder) and the pair settings.
    A pair's fit never depends on the arrival uncertainty (it weighs the fits, in the guards,
    the probes and the pose graph), so the runs that ``stages.join_stations`` makes with it
    widened, from the same starting poses, take the first pass's fits from here instead of
    registering every pair again (a touching plot whose base erred 20 cm / 8 degrees: five
    runs, 87 s of registration). GICP gives the same fit for the same inputs, so a fit taken
    from here is the one registering again would give."""

    def __init__(self) -> None:
        self._fits: dict[tuple[object, ...], PairFit] = {}

    @staticmethod
    def key(job: PairJob, T_field_station: dict[int, Matrix4]) -> tuple[object, ...]:
        """What decides the fit of ``job`` registered from the poses ``T_field_station``."""
        overlap, _, settings, guess, _ = job
        return (
            overlap.a,
            overlap.b,
            np.asarray(T_field_station[overlap.a]).tobytes(),
            np.asarray(T_field_station[overlap.b]).tobytes(),
            None if guess is None else np.asarray(guess).tobytes(),
            settings.model_dump_json(exclude=ARRIVAL_FIELDS),
        )

    def get(self, key: tuple[object, ...]) -> PairFit | None:
        return self._fits.get(key)

    def add(self, key: tuple[object, ...], fit: PairFit) -> None:
        self._fits[key] = fit

    def __len__(self) -> int:
        return len(self._fits)


ARRIVAL_FIELDS = {"arrival_sigma_m", "arrival_sigma_deg"}
"""The registration settings no pair's fit depends on (:class:`PairFits`)."""


def _fits(
    mapper: Callable[..., Iterator[PairFit]],
    jobs: list[PairJob],
    costs: list[float] | None,
    T_field_station: dict[int, Matrix4],
    known: PairFits | None,
) -> Iterator[PairFit]:
    """Each job's fit, in order: from ``known`` where it has the fit, else registered by
    ``mapper`` (a :meth:`ForkedMap.map`, lazily: closing this iterator drops the pairs not
    started) and added to ``known``."""
    if known is None:
        yield from mapper(_register_pair, jobs, costs)
        return
    keys = [PairFits.key(job, T_field_station) for job in jobs]
    todo = [i for i, key in enumerate(keys) if known.get(key) is None]
    fresh = mapper(
        _register_pair, [jobs[i] for i in todo], None if costs is None else [costs[i] for i in todo]
    )
    try:
        for key in keys:
            fit = known.get(key)
            if fit is None:
                fit = next(fresh)
                known.add(key, fit)
            yield fit
    finally:
        close = getattr(fresh, "close", None)
        if close is not None:
            close()


def _pair_costs(overlaps: list[Overlap]) -> list[float]:
    """Each pair's expected cost: its points (a pair's time follows them, correlation 0.93-0.97
    on seeds 1 and 2)."""
    return [float(len(o.points_a_m) + len(o.points_b_m)) for o in overlaps]


def _register_pair(job: PairJob) -> PairFit:
    """:func:`register_overlap` of one ``(overlap, b's centre, settings, guess, threads)``: a
    module-level function of plain data, so a worker process can run it."""
    return register_overlap(*job)


AgreementJob = tuple[Overlap, list[tuple[int, Matrix4, Matrix4]], float]
"""An overlap, for each side to check (side, its move at the coarse pose, corrected), the cap."""
PairMap = Callable[
    [Callable[[AgreementJob], list[tuple[float, float]]], list[AgreementJob], list[float]],
    Iterable[list[tuple[float, float]]],
]
""":meth:`ForkedMap.map` of the guards' checks: (function, jobs, their expected costs)."""


def _pair_agreement(job: AgreementJob) -> list[tuple[float, float]]:
    """The guards' (before, after) terms of each side of one overlap (:meth:`_Plot.agreement`):
    the other side's tree built here, once for the pair, in whichever process runs it."""
    overlap, sides, cap = job
    clouds = (overlap.points_a_m, overlap.points_b_m)
    return [
        _side_terms(overlap, side, cKDTree(clouds[1 - side]), T_before, T_after, cap)
        for side, T_before, T_after in sides
    ]


def _side_terms(
    overlap: Overlap,
    side: int,
    theirs: cKDTree,
    T_before: Matrix4,
    T_after: Matrix4,
    cap: float,
) -> tuple[float, float]:
    """The guards' (before, after) overlap disagreement of side ``side`` of ``overlap`` (every
    :data:`guards.SAMPLE_STRIDE`-th point) moved by ``T_before`` and ``T_after`` onto the other
    side's points (``theirs``)."""
    mine = (overlap.points_a_m, overlap.points_b_m)[side][:: guards.SAMPLE_STRIDE]
    return (
        guards.overlap_disagreement(mine, theirs, T_before, cap),
        guards.overlap_disagreement(mine, theirs, T_after, cap),
    )


def _first_solution(
    nodes: dict[int, Matrix4],
    fits: list[PairFit],
    reference: int,
    settings: RegistrationSettings,
    left_out: set[int],
) -> tuple[list[int], posegraph.Solution]:
    """The graph of every usable fit but those ``left_out`` solved once: (the usable fits'
    indices, the solution)."""
    all_edges, _ = _edges(nodes, fits, reference, settings)
    usable = [k for k in _usable_fits(all_edges, fits, nodes, settings) if k not in left_out]
    edges = [all_edges[k] for k in usable] + all_edges[len(fits) :]
    tolerance = posegraph.Tolerance(settings.edge_tolerance_m, settings.edge_tolerance_deg)
    graph = {MAP_NODE: np.eye(4)} | nodes
    return usable, posegraph.solve(graph, {MAP_NODE}, edges, tolerance, relative_to=reference)


def _consensus_guesses(
    nodes: dict[int, Matrix4],
    fits: list[PairFit],
    first: tuple[list[int], posegraph.Solution],
    settings: RegistrationSettings,
) -> dict[int, Matrix4]:
    """The pairs to register again, each with its relative pose in the ``first`` solution of
    the graph (index into ``fits`` -> ``T_a_b``): the usable fits (plausible for the arrival
    error) that solution drops.

    On smooth relief GICP started at the coarse poses can slide into another minimum (bare
    soil, seed 1: 4 of 20 pairs 13-20 cm off, the rest within 3 mm); the other pairs and the
    priors still place the two stations, and from there the pair finds its true fit. A pair
    whose stations the solution leaves where they started (within the edge tolerance) is not
    registered again: it would only find the same minimum."""
    usable, solution = first
    kept = {usable[i] for i in solution.kept if i < len(usable)}
    correction = {s: solution.T_field_node[s] @ invert(T) for s, T in nodes.items()}
    guesses = {}
    for k in usable:  # a pair beyond the expected arrival error is not tried again
        fit = fits[k]
        if k in kept:
            continue
        guess = invert(correction[fit.a]) @ correction[fit.b]
        moved_m, moved_deg = posegraph.disagreement(
            se3.log(invert(nodes[fit.b]) @ guess @ nodes[fit.b])
        )
        # from where it started (the coarse poses) the pair would only find its minimum again
        if moved_m > settings.edge_tolerance_m or moved_deg > settings.edge_tolerance_deg:
            guesses[k] = guess
    return guesses


def _usable_fits(
    all_edges: list[posegraph.Edge],
    fits: list[PairFit],
    nodes: dict[int, Matrix4],
    settings: RegistrationSettings,
) -> list[int]:
    """Indices of the fits that may enter the graph (:func:`_usable`), ``all_edges`` those of
    :func:`_edges`."""
    return [k for k, f in enumerate(fits) if _usable(f, all_edges[k], nodes, settings)]


def _usable(
    fit: PairFit, edge: posegraph.Edge, nodes: dict[int, Matrix4], settings: RegistrationSettings
) -> bool:
    """A fit goes into the graph when it converged, fits well enough and is plausible: the
    relative correction it asks for lies within ``guard_sigmas`` of the two stations'
    expected arrival errors."""
    if not (fit.converged and fit.fitness >= settings.min_fitness):
        return False
    if fit.points < settings.min_points:
        return False
    expected = guards.prior_covariance(nodes[fit.b], nodes[fit.a], settings)
    return guards.mahalanobis(posegraph.residual(edge, nodes), expected) <= settings.guard_sigmas


MAP_NODE = 0
"""The nominal frame of the plan: the priors tie every station (the reference too) to it."""


def _edges(
    nodes: dict[int, Matrix4],
    fits: list[PairFit],
    reference: int,
    settings: RegistrationSettings,
) -> tuple[list[posegraph.Edge], dict[int, NDArray[np.float64]]]:
    """The pair edges (one per fit, in order), then one prior edge per station from the
    plan's frame (its coarse pose, each station's arrival error independent of the others');
    also each station's expected error relative to the reference."""
    edges = [
        posegraph.Edge(f.a, f.b, invert(nodes[f.a]) @ f.T_a_b @ nodes[f.b], f.information)
        for f in fits
    ]
    information = np.asarray(np.linalg.inv(guards.arrival_covariance(settings)), np.float64)
    for s, T in sorted(nodes.items()):
        edges.append(posegraph.Edge(MAP_NODE, s, T, information, robust=False))
    priors = {
        s: guards.prior_covariance(T, nodes[reference], settings)
        for s, T in nodes.items()
        if s != reference
    }
    return edges, priors


def _solve_plot(
    nodes: dict[int, Matrix4],
    overlaps: list[Overlap],
    fits: list[PairFit],
    reference: int,
    settings: RegistrationSettings,
    T_field_station_coarse: dict[int, Matrix4],
    first: posegraph.Solution | None = None,
    left_out: frozenset[int] | set[int] = frozenset(),
    map_pairs: PairMap | None = None,
) -> dict[int, StationRegistration]:
    """Solve the graph, then fix the station failing its guards worst at its coarse pose and
    solve again, until every free station passes. ``first``: the solution of the graph of
    every usable fit (but those ``left_out``), when already solved. ``map_pairs``: runs the
    overlap checks of each solution a pair at a time (:func:`_pair_agreement`, on a worker
    process too); without it they run here, with one tree of each side kept for every
    solution."""
    all_edges, priors = _edges(nodes, fits, reference, settings)
    usable = [k for k in _usable_fits(all_edges, fits, nodes, settings) if k not in left_out]
    tolerance = posegraph.Tolerance(settings.edge_tolerance_m, settings.edge_tolerance_deg)
    graph = {MAP_NODE: np.eye(4)} | nodes
    fixed: dict[int, str] = {}  # stations kept at their coarse pose, with the reason
    misfits: set[int] = set()  # those kept because the correction did not improve overlaps
    trees: dict[tuple[int, int], cKDTree] = {}  # overlap points, shared by every solution
    while True:
        chosen = [k for k in usable if not {fits[k].a, fits[k].b} & set(fixed)]
        edges = [all_edges[k] for k in chosen] + all_edges[len(fits) :]
        if fixed or first is None:
            solution = posegraph.solve(graph, {MAP_NODE}, edges, tolerance, relative_to=reference)
        else:
            solution = first
        plot = _Plot(
            nodes, priors, overlaps, fits, chosen, solution, settings, reference, fixed, trees
        )
        if map_pairs is not None:
            plot.terms = plot.agreement_terms(map_pairs)
        failure = plot.worst_failure()
        if failure is None:
            break
        station, reason, misfit = failure
        fixed[station] = reason
        if misfit:
            misfits.add(station)
        log.info("station %d kept at its coarse pose: %s", station, reason)
    return {
        s: plot.registration(s, fixed.get(s), T_field_station_coarse[s], s in misfits)
        for s in sorted(nodes)
    }


@dataclass
class _Plot:
    """One solution of the plot's graph and what the guards need to judge it."""

    nodes: dict[int, Matrix4]
    priors: dict[int, NDArray[np.float64]]
    overlaps: list[Overlap]
    fits: list[PairFit]
    chosen: list[int]
    solution: posegraph.Solution
    settings: RegistrationSettings
    reference: int
    fixed: dict[int, str]
    trees: dict[tuple[int, int], cKDTree]
    terms: dict[tuple[int, int], tuple[float, float]] = field(default_factory=dict)
    """(overlap, side) -> that side's (before, after) terms of :meth:`agreement`, computed
    ahead (:meth:`agreement_terms`); the rest are computed when asked for."""

    def correction(self, station: int) -> Matrix4:
        """Field-frame correction of ``station`` relative to the reference station (maps its
        coarse placement onto the solution; identity for the reference and fixed stations)."""
        if station == self.reference or station in self.fixed:
            return np.eye(4)
        poses = self.solution.T_field_node
        C_reference = poses[self.reference] @ invert(self.nodes[self.reference])
        return invert(C_reference) @ poses[station] @ invert(self.nodes[station])

    def kept_fits(self, station: int) -> list[int]:
        """Indices (into ``fits``) of the kept pair edges of ``station``."""
        return [
            self.chosen[k]
            for k in self.solution.kept
            if k < len(self.chosen)
            and station in (self.fits[self.chosen[k]].a, self.fits[self.chosen[k]].b)
        ]

    def limits(self, station: int) -> tuple[float, float]:
        """Largest acceptable correction (m, deg): ``guard_sigmas`` standard deviations."""
        sigma_m, sigma_deg = guards.sigma_m_deg(self.priors[station])
        return self.settings.guard_sigmas * sigma_m, self.settings.guard_sigmas * sigma_deg

    def worst_failure(self) -> tuple[int, str, bool] | None:
        """The free station failing its guards worst: (station, reason, whether the correction
        failed to improve its overlaps); ``None`` when all pass. An implausible correction counts
        before one that does not improve the overlaps."""
        failures: list[tuple[float, int, str, bool]] = []
        for station in sorted(set(self.nodes) - set(self.fixed) - {self.reference}):
            problem = self.guard_problem(station)
            if problem is not None:
                failures.append((problem[0], station, problem[1], problem[2]))
        if not failures:
            return None
        _, station, reason, misfit = max(failures, key=lambda f: (f[0], -f[1]))
        return station, reason, misfit

    def guard_problem(self, station: int) -> tuple[float, str, bool] | None:
        """(severity, reason, whether the correction failed to improve the overlaps) when the
        station's correction fails a guard."""
        implausible = self._implausible(station)
        if implausible is not None:
            return (*implausible, False)
        before, after = self.agreement(station)
        if self.kept_fits(station) and after >= before:
            reason = (
                "the correction does not make the overlaps agree better (RMS "
                f"{1000 * np.sqrt(after):.1f} mm corrected, {1000 * np.sqrt(before):.1f} mm coarse)"
            )
            return 0.0, reason, True
        return None

    def _implausible(self, station: int) -> tuple[float, str] | None:
        """(severity, reason) when the station's correction lies beyond ``guard_sigmas`` of
        its expected arrival error."""
        twist = se3.log(
            invert(self.nodes[station]) @ self.correction(station) @ self.nodes[station]
        )
        sigmas = guards.mahalanobis(twist, self.priors[station])
        if sigmas <= self.settings.guard_sigmas:
            return None
        shift_m, turn_deg = posegraph.disagreement(twist)
        return sigmas, (
            f"correction {1000 * shift_m:.0f} mm / {turn_deg:.2f} deg is {sigmas:.1f} sigma "
            f"of the expected arrival error, its six components together (limit "
            f"{self.settings.guard_sigmas:g} sigma); "
            + guards.most_out(twist, self.priors[station], self.settings.guard_sigmas)
        )

    def agreement(self, station: int) -> tuple[float, float]:
        """Mean squared overlap disagreement (m^2) of ``station`` at its coarse and its
        corrected pose, the neighbours at their solved poses (kept edges only)."""
        before = after = 0.0
        for k in self.kept_fits(station):
            side = 0 if self.overlaps[k].a == station else 1
            term_before, term_after = self.terms.get((k, side)) or _side_terms(
                self.overlaps[k],
                side,
                self.tree(k, 1 - side),
                *self._moves(k, side),
                self.settings.max_correspondence_m,
            )
            before += term_before
            after += term_after
        return before, after

    def _moves(self, k: int, side: int) -> tuple[Matrix4, Matrix4]:
        """How side ``side`` of overlap ``k`` is moved onto the other side's points for
        :meth:`agreement`: at its coarse pose, then corrected, the other at its solved pose."""
        overlap = self.overlaps[k]
        T_other_inverse = invert(self.correction((overlap.b, overlap.a)[side]))
        return T_other_inverse, T_other_inverse @ self.correction((overlap.a, overlap.b)[side])

    def agreement_terms(self, map_pairs: PairMap) -> dict[tuple[int, int], tuple[float, float]]:
        """Every term :meth:`worst_failure` will ask :meth:`agreement` for, a pair at a time
        through ``map_pairs``: the sides of the kept pairs of each free station whose
        correction is plausible. Each term is the same call on the same points and matrices
        as :meth:`agreement`'s, so the guards' verdicts are those of one process."""
        wanted: dict[int, list[int]] = {}
        for station in sorted(set(self.nodes) - set(self.fixed) - {self.reference}):
            if self._implausible(station) is not None:
                continue
            for k in self.kept_fits(station):
                wanted.setdefault(k, []).append(0 if self.overlaps[k].a == station else 1)
        jobs = [
            (
                self.overlaps[k],
                [(side, *self._moves(k, side)) for side in sides],
                self.settings.max_correspondence_m,
            )
            for k, sides in sorted(wanted.items())
        ]
        # a side's cost: a tree of the other side's points, a query of a quarter of its own
        costs = []
        for overlap, sides_moves, _ in jobs:
            clouds = (overlap.points_a_m, overlap.points_b_m)
            costs.append(
                float(
                    sum(len(clouds[1 - side]) + len(clouds[side]) // 4 for side, *_ in sides_moves)
                )
            )
        terms = {}
        for (k, sides), answers in zip(
            sorted(wanted.items()), map_pairs(_pair_agreement, jobs, costs), strict=True
        ):
            terms.update({(k, side): answer for side, answer in zip(sides, answers, strict=True)})
        return terms

    def tree(self, k: int, side: int) -> cKDTree:
        """The k-d tree of side ``side`` (0: a, 1: b) of overlap ``k``'s points, built once."""
        key = (k, side)
        if key not in self.trees:
            overlap = self.overlaps[k]
            self.trees[key] = cKDTree((overlap.points_a_m, overlap.points_b_m)[side])
        return self.trees[key]

    def registration(
        self, station: int, fixed_reason: str | None, T_coarse: Matrix4, misfit: bool = False
    ) -> StationRegistration:
        """The verdict on ``station`` and how it is placed (``fixed_reason``: why it was kept
        at its coarse pose; ``misfit``: because its correction did not improve its overlaps)."""
        kept = self.kept_fits(station)
        linked = {self.fits[k].a for k in kept} | {self.fits[k].b for k in kept}
        coarse = StationRegistration(
            station,
            T_coarse,
            np.eye(4),
            neighbours=sorted(linked - {station}),
            fitness=float(np.mean([self.fits[k].fitness for k in kept])) if kept else None,
            rmse_m=float(np.mean([self.fits[k].rmse_m for k in kept])) if kept else None,
        )
        if station == self.reference:
            return replace(
                coarse,
                accepted=True,
                message="reference",
                verdict=guards.REFERENCE,
                uncertainty_m=0.0,
                uncertainty_deg=0.0,
            )
        limit_m, limit_deg = self.limits(station)
        coarse = replace(coarse, limit_m=limit_m, limit_deg=limit_deg)
        if fixed_reason is not None or not kept:
            sigma_m, sigma_deg = guards.sigma_m_deg(self.priors[station])
            return replace(
                coarse,
                message=f"{fixed_reason or 'no overlap registered'}: coarse pose kept",
                misfit=misfit,
                verdict=guards.COARSE_KEPT
                if self._within(sigma_m, sigma_deg)
                else guards.UNRELIABLE,
                uncertainty_m=sigma_m,
                uncertainty_deg=sigma_deg,
            )
        C = self.correction(station)
        sigma_m, sigma_deg = guards.sigma_m_deg(self.solution.covariance[station])
        refined = self._within(sigma_m, sigma_deg)
        message = f"refined on {len(kept)} overlaps"
        if not refined:
            message += (
                f", but the estimated uncertainty {1000 * sigma_m:.1f} mm / {sigma_deg:.2f} deg "
                "is too large"
            )
        return replace(
            coarse,
            T_field_station=C @ T_coarse,
            T_correction=C,
            accepted=refined,
            message=message,
            verdict=guards.REFINED if refined else guards.UNRELIABLE,
            uncertainty_m=sigma_m,
            uncertainty_deg=sigma_deg,
        )

    def _within(self, sigma_m: float, sigma_deg: float) -> bool:
        return (
            sigma_m <= self.settings.max_uncertainty_m
            and sigma_deg <= self.settings.max_uncertainty_deg
        )


def _coarse_only(
    T_field_station_coarse: dict[int, Matrix4],
    nodes: dict[int, Matrix4],
    reference: int,
    settings: RegistrationSettings,
) -> dict[int, StationRegistration]:
    """Registration off: every station at its coarse pose, with its expected error."""
    registrations = {}
    for station, T in sorted(T_field_station_coarse.items()):
        if station == reference:
            registrations[station] = StationRegistration(
                station,
                T,
                np.eye(4),
                accepted=True,
                message="reference",
                verdict=guards.REFERENCE,
                uncertainty_m=0.0,
                uncertainty_deg=0.0,
            )
            continue
        sigma_m, sigma_deg = guards.sigma_m_deg(
            guards.prior_covariance(nodes[station], nodes[reference], settings)
        )
        registrations[station] = StationRegistration(
            station,
            T,
            np.eye(4),
            message="registration off: coarse pose",
            verdict=guards.COARSE_KEPT,
            uncertainty_m=sigma_m,
            uncertainty_deg=sigma_deg,
        )
    return registrations
