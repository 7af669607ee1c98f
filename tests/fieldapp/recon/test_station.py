import numpy as np
import pytest

from devices.geometry import invert, make_transform, rotation_x, rotation_z, transform_points
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.station import T_view0_view, station_cloud


def _rig(angle_deg: float) -> np.ndarray:
    """A camera on a turntable arm: T_table_camera."""
    R = rotation_x(-120.0)
    return make_transform(R, np.array([0.2, 0.03, 1.3]))


def _T_camera0_camera(angle_deg: float) -> np.ndarray:
    T_table_camera = _rig(0.0)
    turn = make_transform(rotation_z(angle_deg), np.zeros(3))
    return invert(T_table_camera) @ turn @ T_table_camera


@pytest.mark.parametrize("view", [0, 1, 3, 7])
def test_eq9_equals_repeated_step(view: int) -> None:
    step = _T_camera0_camera(45.0)
    np.testing.assert_allclose(
        T_view0_view(step, view), np.linalg.matrix_power(step, view), atol=1e-12
    )
    np.testing.assert_allclose(T_view0_view(step, view), _T_camera0_camera(45.0 * view), atol=1e-12)


def test_negative_view_is_refused() -> None:
    with pytest.raises(ValueError, match="view"):
        T_view0_view(np.eye(4), -1)


def test_station_cloud_puts_one_world_point_seen_from_every_view_in_one_place() -> None:
    step = _T_camera0_camera(45.0)
    world_in_view0 = np.array([[0.3, -0.2, 1.8]])
    views = {}
    for view in range(8):
        in_view = transform_points(invert(_T_camera0_camera(45.0 * view)), world_in_view0)
        views[view] = Cloud(in_view, np.full((1, 3), view, np.uint8))
    joined = station_cloud(views, step)
    np.testing.assert_allclose(joined.points, np.repeat(world_in_view0, 8, axis=0), atol=1e-9)
    assert joined.colors[:, 0].tolist() == list(range(8))
