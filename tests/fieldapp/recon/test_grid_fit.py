"""The planting grid fitted to the stems found: the map frame is only as good as the base's
localisation, and a grid placed by it a decimetre off would put every plant "off the grid"."""

from __future__ import annotations

import numpy as np
import pytest

from devices.geometry import make_transform, rotation_z
from fieldapp.recon.grid import GridNodes, fitted_to_stems, grid_nodes, node_claims
from fieldapp.recon.plants import search_plants
from fieldapp.recon.settings import PlantSettings

from .synthetic import LEAF_RGB, colored
from .touching import plant

SPACING_M = 0.8


def _sown(rng: np.random.Generator, rows: int = 4, columns: int = 4) -> GridNodes:
    """The grid as sown (map frame = truth) and stems within 3 cm of its nodes."""
    return grid_nodes(rows, columns, SPACING_M, SPACING_M, (0.4, 0.4), 0.0, np.eye(4))


def _misplaced(grid: GridNodes, dx: float, dy: float, turn_deg: float) -> GridNodes:
    """``grid`` as a map frame off by a turn about the plot's centre and a shift puts it."""
    centre = grid.xy_m.mean(axis=0)
    R = rotation_z(turn_deg)[:2, :2]
    xy = (grid.xy_m - centre) @ R.T + centre + [dx, dy]
    return GridNodes(xy, grid.row, grid.column, grid.snap_radius_m)


@pytest.mark.parametrize(
    ("dx", "dy", "turn_deg"), [(0.2, -0.15, 0.0), (-0.1, 0.25, 2.5), (0.0, 0.0, 4.0)]
)
def test_a_grid_the_map_frame_puts_beside_its_plants_is_fitted_back_onto_them(
    dx: float, dy: float, turn_deg: float
) -> None:
    rng = np.random.default_rng(3)
    sown = _sown(rng)
    stems = sown.xy_m + rng.uniform(-0.03, 0.03, sown.xy_m.shape)
    off = _misplaced(sown, dx, dy, turn_deg)
    fitted, fit = fitted_to_stems(off, stems)
    assert fit is not None and fit.stems == 16 and fit.applied
    assert np.abs(fitted.xy_m - sown.xy_m).max() < 0.02  # back within the stems' scatter
    moved = np.linalg.norm(off.xy_m - fitted.xy_m, axis=1).max()
    assert fit.moved_m == pytest.approx(moved)
    assert fit.turned_deg == pytest.approx(abs(turn_deg), abs=0.5)


def test_stems_off_the_grid_and_missing_plants_do_not_pull_it() -> None:
    rng = np.random.default_rng(4)
    sown = _sown(rng)
    keep = np.ones(16, dtype=bool)
    keep[[2, 7, 13]] = False  # three plants never came up
    stems = sown.xy_m[keep] + rng.uniform(-0.03, 0.03, (13, 2))
    weeds = sown.xy_m[[0, 5]] + [0.38, 0.3]  # between the rows
    fitted, fit = fitted_to_stems(_misplaced(sown, 0.15, 0.1, 1.5), np.vstack([stems, weeds]))
    assert fit is not None and fit.stems == 13
    assert np.abs(fitted.xy_m - sown.xy_m).max() < 0.02


def test_a_grid_in_place_moves_by_no_more_than_the_stems_scatter() -> None:
    rng = np.random.default_rng(5)
    sown = _sown(rng)
    stems = sown.xy_m + rng.uniform(-0.03, 0.03, sown.xy_m.shape)
    fitted, fit = fitted_to_stems(sown, stems)
    assert fit is not None and fit.moved_m < 0.02
    assert not fit.applied and fitted is sown  # chasing the stems' scatter changes nothing


@pytest.mark.parametrize("count", [0, 2])
def test_too_few_stems_leave_the_grid_as_it_is(count: int) -> None:
    sown = _sown(np.random.default_rng(6))
    off = _misplaced(sown, 0.1, 0.0, 0.0)
    fitted, fit = fitted_to_stems(off, sown.xy_m[:count])
    assert fit is None and fitted is off


def test_a_grid_a_whole_spacing_off_stays_where_the_lattice_fits() -> None:
    """The fit cannot tell a grid from itself moved by a spacing: the map frame must place it
    within half a spacing (40 cm on the 80 cm grid). Stems sitting at the nodes of a grid a
    column off leave it there (cells one column off, as the map frame said)."""
    rng = np.random.default_rng(7)
    sown = _sown(rng)
    stems = sown.xy_m + rng.uniform(-0.03, 0.03, sown.xy_m.shape)
    fitted, fit = fitted_to_stems(_misplaced(sown, SPACING_M, 0.0, 0.0), stems)
    assert fit is not None and fit.stems == 12 and fit.moved_m < 0.03 and not fit.applied
    assert np.abs(fitted.xy_m - sown.xy_m - [SPACING_M, 0.0]).max() < 1e-9


def test_plants_beside_a_misplaced_grid_get_their_cells_and_the_user_is_told() -> None:
    rng = np.random.default_rng(8)
    feet = [(x, y) for y in (0.0, 0.8) for x in (0.0, 0.8, 1.6)]
    points = np.concatenate(
        [plant(rng, foot, [(90.0, 0.12, 0.25, 0.08), (270.0, 0.2, 0.25, 0.08)]) for foot in feet]
    )
    T_field_map = make_transform(rotation_z(1.0), np.array([0.18, -0.12, 0.0]))
    nodes = grid_nodes(2, 3, 0.8, 0.8, (0.0, 0.0), 0.0, T_field_map)  # 12-22 cm off the feet
    assert min(np.hypot(*(nodes.xy_m - foot).T).min() for foot in feet) > 0.15
    search = search_plants(
        colored(points, LEAF_RGB), np.zeros((0, 3)), PlantSettings(), 0.15, nodes
    )
    assert sorted(p.grid_cell for p in search.plants) == [(r, c) for r in (1, 2) for c in (1, 2, 3)]
    assert not search.extra_plants and not search.missing_cells
    [line] = [w for w in search.warnings(0.5) if "grid" in w]
    assert line.startswith("planting grid fitted to 6 stems: it stood up to 2")
    assert search.grid_fit is not None and search.grid_fit.turned_deg == pytest.approx(1.0, abs=0.3)


def test_stems_off_the_grid_and_a_grid_too_far_to_say() -> None:
    """A stem at no node is off the grid (a leaf's end the plants step may then merge); a grid
    with stems at fewer than half of its nodes is no prior at all (``None``)."""
    sown = _sown(np.random.default_rng(0))
    stems = np.concatenate([sown.xy_m[:12] + 0.03, [[0.8, 0.45], [0.42, 0.38]]])
    claims = node_claims(sown, stems)
    assert claims is not None
    # the last stands 2.8 cm from node (1, 1), the first 4.2 cm: both within the snap radius,
    # only the nearer at the node, as plants are placed; (0.8, 0.45) is between two nodes
    assert claims.off.tolist() == [True] + [False] * 11 + [True, False]
    assert claims.node.tolist() == [*range(12), -1, 0]  # both claim node (1, 1)
    assert node_claims(_misplaced(sown, 0.4, 0.4, 0.0), stems) is None
    assert node_claims(sown, stems[:7]) is None  # 7 of 16 nodes
    assert node_claims(sown, stems[:8]) is not None
    assert node_claims(sown, np.empty((0, 2))) is None
