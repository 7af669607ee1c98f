"""A point cloud straight to the plant and trait steps: no capture, no registration.

An imported cloud is taken as already joined (one cloud of the plot or plant, metres, z up).
The steps are the reconstruction's own from levelling on: the ground plane (lowest dominant
plane, RANSAC), the field frame (z = 0 on the ground), plant points (above the ground by the
pass-through height; with colour that has green contrast, also green by ExG and Otsu), voxel
means, outlier removal, plants by clustering, and their traits. The result is written like
``fieldapp reconstruct``'s (``plants.csv``, ``cloud.ply``, ``plants/``, ``report.json``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from devices.geometry import Matrix4, make_transform
from fieldapp.errors import FieldappError
from fieldapp.imports.clouds import LoadedCloud
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.exg import excess_green, otsu_threshold
from fieldapp.recon.filters import split_outliers, voxel_mean, voxel_mean_points
from fieldapp.recon.ground import GroundNotFound, T_level, fit_ground_plane, subsample
from fieldapp.recon.outputs import PlantRow, write_outputs
from fieldapp.recon.plants import Plant, search_plants
from fieldapp.recon.settings import ReconstructionSettings

log = logging.getLogger(__name__)

REPORT_FORMAT = "fieldapp-reconstruction-report/1"
MIN_GREEN_CONTRAST = 0.05
"""ExG spread (90th minus 10th percentile) below which colour cannot tell plants from soil."""
LOWEST_PERCENTILE = 0.5
"""Without a ground plane, the ground is put at this percentile of the heights."""
MAX_BELOW_FRACTION = 0.05
"""A plane with more of the points below it than this is a leaf layer, not the ground."""


@dataclass
class CloudTraits:
    plants: list[Plant]
    cloud: Cloud
    T_field_file: Matrix4
    kept: dict[str, int]
    ground: str
    separation: str
    warnings: list[str] = field(default_factory=list)

    def rows(self) -> list[PlantRow]:
        return [
            PlantRow(
                p.id,
                p.traits.x_m,
                p.traits.y_m,
                p.traits.height_m * 100.0,
                p.traits.width_m * 100.0,
                p.traits.points,
            )
            for p in self.plants
        ]


def T_field_file(
    points_m: NDArray[np.float64], settings: ReconstructionSettings
) -> tuple[Matrix4, str]:
    """The levelling: the ground plane of ``points_m`` (N, 3, z roughly up) to z = 0, and how
    the ground was found. Without a plane (a plant in a pot, cropped), the lowest points."""
    ground = settings.ground
    sample = subsample(points_m, ground.sample_points)
    try:
        plane = fit_ground_plane(
            sample,
            ground.ransac_distance_m,
            ground.ransac_iterations,
            np.array([0.0, 0.0, 1.0]),
            ground.max_tilt_deg,
        )
    except GroundNotFound:
        plane = None
    if plane is not None:
        below = float(np.mean(plane.height_m(sample) < -3 * ground.ransac_distance_m))
        if below > MAX_BELOW_FRACTION or plane.inlier_fraction < ground.min_inlier_fraction / 3:
            plane = None
    if plane is not None:
        return T_level(plane), (
            f"ground plane by RANSAC ({100 * plane.inlier_fraction:.0f} % of the points)"
        )
    z0 = float(np.percentile(points_m[:, 2], LOWEST_PERCENTILE))
    return make_transform(np.eye(3), np.array([0.0, 0.0, -z0])), (
        f"no ground plane: the ground is put at the lowest points (z = {z0:.3f} m of the file)"
    )


def plant_mask(
    levelled: Cloud, has_color: bool, min_height_m: float
) -> tuple[NDArray[np.bool_], str]:
    """Points that belong to plants, and how they were told from the soil."""
    above = levelled.points[:, 2] >= min_height_m
    if has_color:
        exg = excess_green(levelled.colors)
        low, high = np.percentile(exg, [10, 90])
        if high - low >= MIN_GREEN_CONTRAST:
            threshold = otsu_threshold(exg)
            return above & (exg > threshold), (
                f"green (ExG > {threshold:.3f}, Otsu) and "
                f"{100 * min_height_m:g} cm above the ground"
            )
    why = "no colour" if not has_color else "no green contrast in the colour"
    return above, f"geometry only ({why}): {100 * min_height_m:g} cm above the ground"


def cloud_traits(
    loaded: LoadedCloud, settings: ReconstructionSettings, min_height_m: float
) -> CloudTraits:
    """Plants and traits of an imported cloud."""
    cloud = loaded.cloud
    T, ground = T_field_file(cloud.points, settings)
    levelled = cloud.transformed(T)
    keep = levelled.points[:, 2] <= settings.filters.pass_through_max_m
    mask, separation = plant_mask(levelled, loaded.has_color, min_height_m)
    kept = {"points": len(cloud), "plant_points": int((mask & keep).sum())}
    soil_m = levelled.points[np.abs(levelled.points[:, 2]) <= settings.ground.soil_band_m]
    plants_cloud = voxel_mean(levelled.select(mask & keep), settings.filters.voxel_size_m)
    kept["voxel_mean"] = len(plants_cloud)
    plants_cloud, doubtful, counts = split_outliers(
        plants_cloud, settings.filters, settings.threads
    )
    soil_m = voxel_mean_points(soil_m, settings.ground.soil_voxel_m)
    if len(soil_m) == 0:
        soil_m = np.zeros((1, 3))
    search = search_plants(
        plants_cloud,
        soil_m,
        settings.plants,
        settings.ground.local_ground_radius_m,
        doubtful=doubtful,
    )
    plants = search.plants
    plants_cloud = search.cloud if search.cloud is not None else plants_cloud
    counts["doubtful_joined"] = search.joined
    result = CloudTraits(plants, plants_cloud, T, kept | counts, ground, separation)
    if not plants:
        result.warnings.append(
            f"no plant found: {kept['plant_points']} points were taken as plant ({separation})"
            "; check --units and --up"
        )
    return result


def write_cloud_results(out: Path, source: Path, result: CloudTraits) -> list[Path]:
    """``plants.csv``, ``cloud.ply``, ``plants/``, ``report.json`` as a reconstruction writes."""
    report: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "session": source.stem,
        "source": {"point_cloud": str(source.resolve())},
        "plants": len(result.plants),
        "T_field_file": result.T_field_file.tolist(),
        "ground": result.ground,
        "plant_separation": result.separation,
        "points_kept": result.kept,
        "warnings": result.warnings,
    }
    if out.exists() and not out.is_dir():
        raise FieldappError(f"--out: {out} exists and is not a folder")
    return write_outputs(
        out, result.rows(), result.cloud, {p.id: p.cloud for p in result.plants}, report
    )
