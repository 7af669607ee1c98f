"""Corrections seen in 3D: the stems of a split picked by clicking the plant in the 3D view
(a click at a point's projection picks what the ray from the camera meets first), the picked
stems drawn; the plants selected or made by a correction highlighted by exactly their points
(the per-point plant of the results folder, not a distance to the base); the operator field
labelled."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from PySide6 import QtCore, QtWidgets

from fieldapp.io.durable import write_bytes_durably
from fieldapp.recon.outputs import ply_bytes, read_labelled_ply
from fieldapp.results.corrections import read_corrections
from ui.results import view3d
from ui.results.data import load_results_dir
from ui.results.scene import FRONT_M, build_scene, depth_m, pick_on_screen

from ...fieldapp.results.seedlings import STEMS
from .correcting import open_copy, select, settled, table


def test_a_click_picks_the_nearest_point_in_front():
    pixels = np.array([[100.0, 100.0], [101.0, 100.0], [104.0, 100.0], [300.0, 40.0], [np.nan] * 2])
    depth = np.array([2.0, 2.5, 2.0 + FRONT_M / 2, 1.0, 0.5])
    assert pick_on_screen((101.0, 100.0), pixels, depth) == 0  # 1 is nearer but behind 0
    assert pick_on_screen((103.0, 100.0), pixels, depth) == 2  # 0 and 2 both in front
    assert pick_on_screen((101.0, 100.0), pixels) == 1  # no depth: the nearest on screen
    assert pick_on_screen((300.0, 47.0), pixels, depth) is None  # 7 px: too far
    assert pick_on_screen((300.0, 45.0), pixels, depth) == 3
    assert pick_on_screen((0.0, 0.0), pixels[:0]) is None


def test_points_belong_to_their_plants_exactly(plots, tmp_path):
    """A cloud written without per-point labels (organs not measured): each point's plant is
    found from plants/<plant>.ply; a plant wider than its base's circle keeps all its points."""
    folder = open_copy_plain(plots, "merged", tmp_path)
    truth = read_labelled_ply(plots["merged"] / "cloud.ply")[1].plant_id
    results = load_results_dir(folder)
    assert results.point_plants is None
    assert np.array_equal(results.plant_of_point(), truth)
    scene = build_scene(results)
    assert np.array_equal(scene.plant_of_point, truth) and (truth == 1).all()
    labelled = load_results_dir(plots["apart"])  # labels in cloud.ply: taken as they are
    assert labelled.point_plants is not None
    assert np.bincount(labelled.point_plants).tolist() == [0, 3000, 3000]


def open_copy_plain(plots, name, tmp_path):
    """A copy of ``plots[name]`` whose cloud.ply has no per-point labels."""
    folder = shutil.copytree(plots[name], tmp_path / name)
    cloud = read_labelled_ply(folder / "cloud.ply")[0]
    write_bytes_durably(folder / "cloud.ply", ply_bytes(cloud))
    return folder


def _highlighted(panel) -> int:
    """How many points the side view draws highlighted (offscreen: no OpenGL)."""
    return len(panel.view3d.view.selected.getData()[0])


def test_plants_selected_and_merged_are_highlighted_by_their_points(qtbot, panel, plots, tmp_path):
    open_copy(panel, plots, "apart", tmp_path)
    sizes = {p: len(c) for p, c in panel.results.plant_clouds.items()}
    select(panel, 1, 2)
    assert _highlighted(panel) == sizes[1] + sizes[2]
    assert panel.map.highlighted == {1, 2}
    panel.correction.merge_action.trigger()
    settled(qtbot, panel)
    assert list(table(panel)) == [1] and panel.correction.selected_plants() == [1]
    assert _highlighted(panel) == sizes[1] + sizes[2]  # the merged plant: every point
    merged = panel.view3d.scene.colors_for([1])
    assert np.allclose(merged, panel.view3d.scene.colors_for(1))
    panel.correction.undo_action.trigger()
    settled(qtbot, panel)
    assert panel.correction.selected_plants() == [1, 2]  # what undoing gave back
    select(panel, 2)
    assert _highlighted(panel) == sizes[2] and panel.map.highlighted == {2}


@pytest.fixture
def gl_panel(monkeypatch, request):
    """The panel with its 3D view (OpenGL widget; on the offscreen platform it draws nothing,
    but its camera, projection and mouse handling are the real ones)."""
    monkeypatch.setattr(view3d, "gl_available", lambda: True)
    panel = request.getfixturevalue("panel")
    assert panel.view3d.is_3d
    panel.view3d.view.widget.resize(900, 650)
    return panel


def _visible_stem_pixel(widget, points_m, stem_xy_m) -> QtCore.QPoint:
    """Where the stem at ``stem_xy_m`` is seen: the pixel of its point nearest the camera of
    those no other point hides (nothing within 10 px on screen more than 1 cm in front)."""
    pixels, depth = widget.to_screen(points_m), depth_m(points_m, widget.mvp())
    on_stem = np.hypot(*(points_m[:, :2] - stem_xy_m).T) < 0.009
    for i in np.flatnonzero(on_stem)[np.argsort(depth[on_stem])]:
        near = np.hypot(*(pixels - pixels[i]).T) < 10
        if depth[near].min() >= depth[i] - 0.01:
            return QtCore.QPoint(round(pixels[i, 0]), round(pixels[i, 1]))
    raise AssertionError(f"no point of the stem at {stem_xy_m} is visible")


def test_split_by_picking_the_stems_in_the_3d_view(qtbot, gl_panel, plots, tmp_path):
    panel = gl_panel
    folder = open_copy(panel, plots, "merged", tmp_path)
    bar, view = panel.correction, panel.view3d
    select(panel, 1)
    bar.split_action.trigger()
    assert view.picking and panel.tabs.currentWidget() is view and not bar.split_row.isHidden()
    assert not bar.picker.apply.isEnabled()
    widget = view.view.widget
    points = panel.results.plant_clouds[1].points
    picked = []
    view.point_picked.connect(picked.append)
    qtbot.mouseClick(widget, QtCore.Qt.MouseButton.LeftButton, pos=QtCore.QPoint(3, 3))
    assert not picked and "no point of plant 1 there" in bar.picker.count.text()
    panel.map.point_clicked.emit(STEMS[1][0], STEMS[1][1] + 0.2)  # a click on the map, off it
    assert bar.stems.text() == "" and "cm from plant 1: click on" in bar.picker.count.text()
    for stem in STEMS:
        pixel = _visible_stem_pixel(widget, points, np.array(stem))
        qtbot.mouseClick(widget, QtCore.Qt.MouseButton.LeftButton, pos=pixel)
    assert len(picked) == 2
    for point, stem in zip(picked, STEMS, strict=True):
        assert np.hypot(*(point[:2] - stem)) < 0.02  # the stem clicked, not a leaf
    assert np.allclose(view.view.markers.pos, picked)  # drawn where picked
    assert len(panel.map.markers.data) == 2
    assert bar.picker.apply.isEnabled() and "2 stems" in bar.picker.count.text()
    assert panel.selected == 1  # a click while picking selects no plant
    bar.picker.apply.click()
    settled(qtbot, panel)
    assert list(table(panel)) == [1, 2]
    assert table(panel)[2].x_m == pytest.approx(STEMS[1][0], abs=0.02)
    assert not view.picking and len(view.view.markers.pos) == 0
    stem_labels = [w for w in widget.findChildren(QtWidgets.QLabel) if w.text().startswith("stem")]
    assert not [w for w in stem_labels if not w.isHidden()]  # the markers' numbers gone too
    assert panel.correction.selected_plants() == [1, 2]
    assert [op.kind for op in read_corrections(folder).operations] == ["split"]


def test_a_click_out_of_split_selects_a_plant_in_the_3d_view(qtbot, gl_panel, plots, tmp_path):
    panel = gl_panel
    open_copy(panel, plots, "apart", tmp_path)
    widget = panel.view3d.view.widget
    label = widget.to_screen(panel.view3d.scene.label(2).position_m[None])[0]
    qtbot.mouseClick(
        widget, QtCore.Qt.MouseButton.LeftButton, pos=QtCore.QPoint(*np.round(label).astype(int))
    )
    assert panel.selected == 2


def test_the_operator_field_is_labelled(panel):
    bar = panel.correction
    assert bar.author_label.text().strip() == "Corrected by:"
    assert bar.author_label.buddy() is bar.author
    for tip in (bar.author.toolTip(), bar.author_label.toolTip()):
        assert "corrections.json" in tip and "results database" in tip


def test_without_opengl_the_side_view_picks_too(qtbot, plots):
    """The fallback side view (x against height) picks the same way."""
    view = view3d.CloudView()
    qtbot.addWidget(view)
    assert not view.is_3d  # the offscreen platform has no OpenGL
    results = load_results_dir(plots["merged"])
    view.show_scene(build_scene(results))
    view.resize(800, 600)
    view.show()
    qtbot.waitExposed(view)
    points = results.plant_clouds[1].points
    view.start_picking(points)
    picked, missed = [], []
    view.point_picked.connect(picked.append)
    view.pick_missed.connect(lambda: missed.append(True))
    side = view.view
    qtbot.waitUntil(lambda: side.plotItem.vb.viewRect().width() > 0.1)
    top = np.argmax(np.where(np.hypot(*(points[:, :2] - STEMS[1]).T) < 0.01, points[:, 2], -1))
    for x_m, z_m in ((points[top, 0], points[top, 2] - 0.005), (0.15, 0.5)):  # stem, then air
        scene_point = side.plotItem.vb.mapViewToScene(QtCore.QPointF(x_m, z_m))
        click = side.mapFromScene(scene_point)
        qtbot.mouseClick(side.viewport(), QtCore.Qt.MouseButton.LeftButton, pos=click)
    assert len(picked) == 1 and missed == [True]
    assert np.hypot(*(picked[0][:2] - STEMS[1])) < 0.01
    view.stop_picking()
    view.close()
