"""``fieldapp simulate`` writes the plan a mission would: stations and the planting grid (map)."""

from __future__ import annotations

import numpy as np

from devices.geometry import invert
from devices.sim.rig import RigGeometry
from devices.sim.scene import PlotLayout, plot_scene
from fieldapp.cli.simulate import simulated_plan
from fieldapp.io.planting import SessionPlan
from fieldapp.recon.grid import plan_nodes


def test_the_simulated_plan_holds_the_grid_the_plants_were_sown_on() -> None:
    rig = RigGeometry()
    plan = SessionPlan.model_validate(simulated_plan(rig))  # the reconstruction's reader
    grid = plan.planting_grid
    assert grid is not None and grid.expected_plants == 16
    assert [s.number for s in plan.stations] == list(rig.stations)
    nodes = plan_nodes(grid, np.eye(4))  # in the map frame
    T_map_field = invert(rig.T_field_map)
    for seed in (0, 3):
        plants = plot_scene(seed).plants
        map_xy = np.array([[p.x_m, p.y_m] for p in plants]) @ T_map_field[:2, :2].T
        map_xy += T_map_field[:2, 3]
        distance = np.hypot(*(map_xy[:, None] - nodes.xy_m[None]).transpose(2, 0, 1))
        nearest = np.argmin(distance, axis=1)
        assert sorted(nearest) == list(range(16))  # one plant per node
        assert distance.min(axis=1).max() <= np.sqrt(2) * PlotLayout().jitter_m


def test_a_larger_plot_gets_its_larger_grid() -> None:
    grid = SessionPlan.model_validate(simulated_plan(RigGeometry(grid=5))).planting_grid
    assert grid is not None and (grid.rows, grid.columns) == (8, 8)
    assert (grid.origin.x, grid.origin.y) == (0.4, 0.4)  # station 1 at the map origin
