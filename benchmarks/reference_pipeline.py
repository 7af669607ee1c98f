"""The honest reference for ``bench_reconstruct.py``: the paper's method as a competent engineer
writes it in an afternoon with plain Open3D calls, in the paper's own order.

Per view: ``PointCloud.create_from_rgbd_image`` (depth cropped at 2.25 m), moved by the pre-
calibration (view step chained, Eq. 9; station to reference; reference to the levelled field
frame). Per station, before anything is registered: a RANSAC ground plane (on a 1 cm voxel
copy, whose inliers are kept as the station's soil sample), pass-through between 1 cm and
1.5 m above it, excess green with Otsu's threshold, a 2 mm voxel grid (the eight views
overlap), statistical (k = 35, 1.5 sigma) and radius (5 points in 8 mm) outlier removal. Then
each station, nearest first, registered by point-to-plane ICP (5 cm, then 2 cm) onto the
stations already placed, on their overlap region; DBSCAN (5 cm, 10 points), a cluster being a
plant when it holds a tenth of the largest cluster's points; per plant the width as the
diameter of the smallest enclosing circle of its points seen from above, placed at that
circle's centre, and the height of its top above the median soil height in a ring around
it. Positions are written in the map frame by the reference station's base pose, as
fieldapp's ``plants.csv`` is (the field frame without base poses).

This is what fieldapp is measured against. It is not a straw man: every step is the library's
own, on clouds already reduced to plants, as the paper does it; on simulated seeds 0-4 it
finds all 16 plants with no phantom (``docs/RECONSTRUCTION.md``, "Speed").

Before issue 22's review it wrote its positions in the field frame while the truth pairs
plants in the map frame (1.6 m away on the standard plot: 4 of 16 plants "found", each the
wrong one), kept every DBSCAN cluster of 200 points (soil specks and leaf fragments), placed a
plant at its lowest points (a drooping leaf tip) and measured every height from the
reference station's ground plane (the soil is uneven by several cm across a plot).
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
DBSCAN_EPS_M = 0.05
"""25 voxels: leaves of one plant join through their 2 mm voxels; neighbours stay apart
(seedlings 80 cm apart leave gaps of 30 cm and more)."""
DBSCAN_MIN_POINTS = 10
ROR_VOXELS = 4
"""The radius filter keeps points with 5 others within 4 voxels (8 mm at 2 mm)."""
MIN_PLANT_SHARE = 0.1
"""A cluster is a plant when it has a tenth of the largest cluster's points: on seeds 0-4
plants had 2,900-10,800 points and the fragments (leaf tips cut off by the outlier
filters, weeds) 15-650."""
GROUND_RING_M = 0.3
OVERLAP_MARGIN_M = 0.10


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


def _ground(cloud: o3d.geometry.PointCloud) -> tuple[np.ndarray, o3d.geometry.PointCloud]:
    """RANSAC plane (a, b, c, d) with the normal up and unit length, fitted on a 1 cm voxel
    copy (the eight views repeat the soil many times over), and that copy's inliers: the
    station's soil sample, from which each plant's own ground height is taken."""
    sample = cloud.voxel_down_sample(RANSAC_VOXEL_M)
    plane, inliers = sample.segment_plane(
        distance_threshold=RANSAC_VOXEL_M, ransac_n=3, num_iterations=300
    )
    plane = np.asarray(plane, np.float64) / np.linalg.norm(plane[:3])
    return (-plane if plane[2] < 0 else plane), sample.select_by_index(inliers)


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


def plants_of_station(
    cloud: o3d.geometry.PointCloud, voxel_m: float = VOXEL_M
) -> tuple[o3d.geometry.PointCloud, o3d.geometry.PointCloud]:
    """Pass-through above the station's RANSAC ground, ExG, voxel grid, SOR, ROR; the plants
    and the station's soil sample (the ground's inliers)."""
    plane, soil = _ground(cloud)
    height = _heights(np.asarray(cloud.points), plane)
    above = np.flatnonzero((height > PASS_THROUGH_M[0]) & (height < PASS_THROUGH_M[1]))
    crop = cloud.select_by_index(above)
    green = _excess_green_mask((np.asarray(crop.colors) * 255).astype(np.uint8))
    plants = crop.select_by_index(np.flatnonzero(green)).voxel_down_sample(voxel_m)
    plants, _ = plants.remove_statistical_outlier(nb_neighbors=35, std_ratio=1.5)
    plants, _ = plants.remove_radius_outlier(nb_points=5, radius=ROR_VOXELS * voxel_m)
    return plants, soil


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


def plant_traits(
    cloud: o3d.geometry.PointCloud, soil: o3d.geometry.PointCloud
) -> list[dict[str, float]]:
    """DBSCAN; clusters of at least a tenth of the largest are plants (the rest are leaf
    fragments and weeds), each placed at the centre of the smallest circle enclosing it from
    above (its width the circle's diameter), its height its top above the median soil
    height in a ring around that circle (the soil is uneven across a plot)."""
    labels = np.asarray(cloud.cluster_dbscan(eps=DBSCAN_EPS_M, min_points=DBSCAN_MIN_POINTS))
    points, soil_m = np.asarray(cloud.points), np.asarray(soil.points)
    sizes = np.bincount(labels[labels >= 0]) if labels.size and labels.max() >= 0 else []
    rows = []
    for label, size in enumerate(sizes):
        if size < MIN_PLANT_SHARE * max(sizes):
            continue
        member = points[labels == label]
        (x, y), radius = cv2.minEnclosingCircle(member[:, :2].astype(np.float32))
        distance = np.hypot(soil_m[:, 0] - x, soil_m[:, 1] - y)
        ring = soil_m[(distance > radius) & (distance < radius + GROUND_RING_M)]
        ground_m = float(np.median(ring[:, 2])) if len(ring) else 0.0
        rows.append(
            {
                "x_m": float(x),
                "y_m": float(y),
                "height_cm": max(float(member[:, 2].max() - ground_m) * 100, 0.0),
                "width_cm": float(2 * radius * 100),
                "points": len(member),
            }
        )
    return rows


def T_map_field(session: Session, reference: int) -> np.ndarray:
    """The field frame (the reference station's base, by the ground calibration) on the map:
    the base pose the reference station's captures report (x, y, yaw), else the identity."""
    poses = [c.base_pose for c in session.captures if c.station == reference and c.base_pose]
    T = np.eye(4)
    if poses:
        yaw = np.radians(np.mean([p.yaw_deg for p in poses]))
        T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        T[:2, 3] = np.mean([p.x for p in poses]), np.mean([p.y for p in poses])
    return T


def reconstruct(folder: Path, out: Path, voxel_m: float = VOXEL_M) -> dict[str, Any]:
    """Run the reference on ``folder`` with plant voxels of ``voxel_m`` (the radius filter's
    radius scales with it); writes ``out/plants.csv``; returns the stage times."""
    stages = Stages()
    session = load_session(folder)
    clouds = station_clouds(session)
    stages.done("views -> clouds (create_from_rgbd_image)")
    plants, soil = {}, {}
    for station, cloud in clouds.items():
        plants[station], soil[station] = plants_of_station(cloud, voxel_m)
    stages.done("per station: RANSAC, pass-through, ExG, voxel, SOR, ROR")
    stations = session.calibration.stations
    assert stations is not None
    reference = stations.reference
    centres = {s: np.asarray(c.get_center()) for s, c in clouds.items()}
    corrections = register_stations(plants, reference, centres)
    stages.done("ICP on overlaps")
    merged, ground = o3d.geometry.PointCloud(), o3d.geometry.PointCloud()
    for station, cloud in plants.items():
        merged += cloud
        ground += soil[station].transform(corrections[station])
    rows = plant_traits(merged.voxel_down_sample(voxel_m), ground)
    T = T_map_field(session, reference)
    for row in rows:  # plants.csv is in the map frame when the base reported its poses
        row["x_m"], row["y_m"] = T[:2, :2] @ (row["x_m"], row["y_m"]) + T[:2, 3]
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
