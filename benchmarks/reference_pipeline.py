"""The honest reference for ``bench_reconstruct.py``: the paper's method as a competent engineer
writes it in an afternoon with plain Open3D calls, in the paper's own order.

Per view: ``PointCloud.create_from_rgbd_image`` (depth cropped at 2.25 m), moved by the pre-
calibration (view step chained, Eq. 9; station to reference; reference to the levelled field
frame). Per station, before anything is registered: a RANSAC ground plane (on a 1 cm voxel
copy), pass-through between 1 cm and 1.5 m above it, excess green with Otsu's threshold, a 2 mm
voxel grid (the eight views overlap), statistical (k = 35, 1.5 sigma) and radius (5 points in 8
mm) outlier removal. Then each station, nearest first, registered by point-to-plane ICP (5 cm,
then 2 cm) onto the stations already placed, on their overlap region; DBSCAN (5 cm, 10 points);
per cluster the height above the reference station's ground plane and the width as the diameter
of the smallest enclosing circle of its points seen from above.

This is what fieldapp is measured against. It is not a straw man: every step is the library's
own, on clouds already reduced to plants, as the paper does it.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import open3d as o3d

from fieldapp.io.session import Session, load_session

DEPTH_TRUNC_M = 2.25
PASS_THROUGH_M = (0.01, 1.5)
VOXEL_M = 0.002
RANSAC_VOXEL_M = 0.01
DBSCAN_EPS_M = 0.05  # plants stand 80 cm apart: gaps of 30 cm and more between seedlings
OVERLAP_MARGIN_M = 0.10
MIN_CLUSTER_POINTS = 200


class Stages:
    """Wall and CPU seconds per named stage."""

    def __init__(self) -> None:
        self.wall_s: dict[str, float] = {}
        self.cpu_s: dict[str, float] = {}
        self._last = (time.perf_counter(), time.process_time())

    def done(self, name: str) -> None:
        now = (time.perf_counter(), time.process_time())
        self.wall_s[name] = self.wall_s.get(name, 0.0) + now[0] - self._last[0]
        self.cpu_s[name] = self.cpu_s.get(name, 0.0) + now[1] - self._last[1]
        self._last = now


def _excess_green_mask(colors: np.ndarray) -> np.ndarray:
    """ExG = 2g - r - b on chromatic coordinates, thresholded by Otsu (OpenCV)."""
    rgb = colors.astype(np.float64)
    chroma = rgb / np.maximum(rgb.sum(axis=1, keepdims=True), 1e-9)
    exg = 2 * chroma[:, 1] - chroma[:, 0] - chroma[:, 2]
    scaled = np.clip((exg + 1.0) * 127.5, 0, 255).astype(np.uint8).reshape(-1, 1)
    threshold, _ = cv2.threshold(scaled, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return scaled.ravel() > threshold


def _ground_plane(cloud: o3d.geometry.PointCloud) -> np.ndarray:
    """RANSAC plane (a, b, c, d) with the normal up and unit length, fitted on a 1 cm voxel
    copy (the eight views repeat the soil many times over)."""
    sample = cloud.voxel_down_sample(RANSAC_VOXEL_M)
    plane, _ = sample.segment_plane(distance_threshold=0.01, ransac_n=3, num_iterations=300)
    plane = np.asarray(plane, np.float64) / np.linalg.norm(plane[:3])
    return -plane if plane[2] < 0 else plane


def _heights(points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    return points @ plane[:3] + plane[3]


def station_clouds(session: Session) -> dict[int, o3d.geometry.PointCloud]:
    """Every station's views as one cloud in the field frame, by the pre-calibration."""
    calibration = session.calibration
    if calibration.view_step is None or calibration.stations is None:
        raise ValueError("the reference needs a view step and station calibration")
    camera = calibration.depth_camera
    intrinsic = o3d.camera.PinholeCameraIntrinsic(
        camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
    )
    T_field_reference = calibration.ground.matrix if calibration.ground else np.eye(4)
    clouds: dict[int, o3d.geometry.PointCloud] = {}
    for capture in session.captures:
        if capture.color is None:
            continue
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.io.read_image(str(session.path_of(capture.color))),
            o3d.io.read_image(str(session.path_of(capture.depth))),
            depth_scale=camera.depth_scale,
            depth_trunc=DEPTH_TRUNC_M,
            convert_rgb_to_intensity=False,
        )
        cloud = o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, intrinsic)
        T_reference_station = calibration.stations.to_reference[capture.station]
        view = calibration.view_step.T_view0_view(capture.view)
        cloud.transform(T_field_reference @ T_reference_station @ view)
        clouds.setdefault(capture.station, o3d.geometry.PointCloud())
        clouds[capture.station] += cloud
    return clouds


def plants_of_station(cloud: o3d.geometry.PointCloud) -> tuple[o3d.geometry.PointCloud, Any]:
    """Pass-through above the station's RANSAC ground, ExG, voxel grid, SOR, ROR."""
    plane = _ground_plane(cloud)
    height = _heights(np.asarray(cloud.points), plane)
    above = np.flatnonzero((height > PASS_THROUGH_M[0]) & (height < PASS_THROUGH_M[1]))
    crop = cloud.select_by_index(above)
    green = _excess_green_mask((np.asarray(crop.colors) * 255).astype(np.uint8))
    plants = crop.select_by_index(np.flatnonzero(green)).voxel_down_sample(VOXEL_M)
    plants, _ = plants.remove_statistical_outlier(nb_neighbors=35, std_ratio=1.5)
    plants, _ = plants.remove_radius_outlier(nb_points=5, radius=0.008)
    return plants, plane


def _overlap(
    a: o3d.geometry.PointCloud, b: o3d.geometry.PointCloud
) -> tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud] | None:
    box_a, box_b = a.get_axis_aligned_bounding_box(), b.get_axis_aligned_bounding_box()
    low = np.maximum(box_a.min_bound, box_b.min_bound) - OVERLAP_MARGIN_M
    high = np.minimum(box_a.max_bound, box_b.max_bound) + OVERLAP_MARGIN_M
    if np.any(low >= high):
        return None
    box = o3d.geometry.AxisAlignedBoundingBox(low, high)
    return a.crop(box), b.crop(box)


def register_stations(
    plants: dict[int, o3d.geometry.PointCloud], reference: int, centres: dict[int, np.ndarray]
) -> dict[int, np.ndarray]:
    """ICP of each station (nearest to the reference first) onto those already placed."""
    placed = o3d.geometry.PointCloud(plants[reference])
    corrections = {reference: np.eye(4)}
    order = sorted(plants, key=lambda s: float(np.linalg.norm(centres[s] - centres[reference])))
    for station in order:
        if station == reference:
            continue
        pair = _overlap(plants[station], placed)
        T = np.eye(4)
        if pair is not None and len(pair[0].points) > 50 and len(pair[1].points) > 50:
            source, target = pair
            target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.02, max_nn=30))
            for distance in (0.05, 0.02):
                T = o3d.pipelines.registration.registration_icp(
                    source,
                    target,
                    distance,
                    T,
                    o3d.pipelines.registration.TransformationEstimationPointToPlane(),
                ).transformation
        plants[station].transform(T)
        corrections[station] = T
        placed += plants[station]
    return corrections


def plant_traits(cloud: o3d.geometry.PointCloud, plane: np.ndarray) -> list[dict[str, float]]:
    """DBSCAN, then per cluster: position, height above the ground plane, enclosing width."""
    labels = np.asarray(cloud.cluster_dbscan(eps=DBSCAN_EPS_M, min_points=10))
    points = np.asarray(cloud.points)
    rows = []
    for label in range(int(labels.max()) + 1 if labels.size else 0):
        member = points[labels == label]
        if len(member) < MIN_CLUSTER_POINTS:
            continue
        height = _heights(member, plane)
        (_, _), radius = cv2.minEnclosingCircle(member[:, :2].astype(np.float32))
        base = member[height <= height.min() + 0.02]
        rows.append(
            {
                "x_m": float(base[:, 0].mean()),
                "y_m": float(base[:, 1].mean()),
                "height_cm": float(height.max() * 100),
                "width_cm": float(2 * radius * 100),
                "points": len(member),
            }
        )
    return rows


def reconstruct(folder: Path, out: Path) -> dict[str, Any]:
    """Run the reference on ``folder``; writes ``out/plants.csv``; returns the stage times."""
    stages = Stages()
    session = load_session(folder)
    clouds = station_clouds(session)
    stages.done("views -> clouds (create_from_rgbd_image)")
    plants, planes = {}, {}
    for station, cloud in clouds.items():
        plants[station], planes[station] = plants_of_station(cloud)
    stages.done("per station: RANSAC, pass-through, ExG, voxel, SOR, ROR")
    stations = session.calibration.stations
    assert stations is not None
    reference = stations.reference
    centres = {s: np.asarray(c.get_center()) for s, c in clouds.items()}
    register_stations(plants, reference, centres)
    stages.done("ICP on overlaps")
    merged = o3d.geometry.PointCloud()
    for cloud in plants.values():
        merged += cloud
    rows = plant_traits(merged.voxel_down_sample(VOXEL_M), planes[reference])
    stages.done("DBSCAN + traits")
    out.mkdir(parents=True, exist_ok=True)
    with (out / "plants.csv").open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["plant", "x_m", "y_m", "height_cm", "width_cm", "points"])
        for number, row in enumerate(rows, start=1):
            writer.writerow(
                [
                    number,
                    *(f"{row[k]:.4f}" for k in ("x_m", "y_m")),
                    *(f"{row[k]:.2f}" for k in ("height_cm", "width_cm")),
                    row["points"],
                ]
            )
    return {"stages_wall_s": stages.wall_s, "stages_cpu_s": stages.cpu_s}
