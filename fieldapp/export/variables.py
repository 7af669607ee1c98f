"""The observed variables (MIAPPE: trait, method, scale) of the ``plants.csv`` columns."""

from __future__ import annotations

import re
from dataclasses import dataclass

UNITS = {
    "m": "m",
    "cm": "cm",
    "mm": "mm",
    "cm2": "cm2",
    "deg": "degree",
    "count": "count",
}
"""Column-name suffixes and the unit each names."""


@dataclass(frozen=True)
class Variable:
    """One observed variable: ``column`` of plants.csv, its ``name``, trait, method and unit."""

    column: str
    name: str
    trait: str
    method: str
    unit: str

    @property
    def variable_id(self) -> str:
        return f"fieldapp:{self.column}"


KNOWN = {
    "height_cm": Variable(
        "height_cm",
        "plant_height_cm",
        "plant height",
        "top of the plant's reconstructed point cloud above the local ground at its base "
        "(Kinect v2 turntable scans joined by calibrated transforms and ICP; fieldapp "
        "reconstruct)",
        "cm",
    ),
    "width_cm": Variable(
        "width_cm",
        "plant_width_cm",
        "plant width",
        "diameter of the smallest circle enclosing the plant's points projected on the "
        "ground plane (fieldapp reconstruct)",
        "cm",
    ),
    "leaf_count": Variable(
        "leaf_count",
        "leaf_count",
        "number of leaves",
        "leaves segmented in the plant's point cloud (fieldapp reconstruct)",
        "count",
    ),
    "leaf_area_cm2": Variable(
        "leaf_area_cm2",
        "leaf_area_cm2",
        "leaf area",
        "sum of the segmented leaves' surface areas (fieldapp reconstruct)",
        "cm2",
    ),
    "stem_diameter_mm": Variable(
        "stem_diameter_mm",
        "stem_diameter_mm",
        "stem diameter",
        "circle fitted to the stem's points near its base (fieldapp reconstruct)",
        "mm",
    ),
}

NOT_TRAITS = {
    "plant",
    "plant_id",
    "x_m",
    "y_m",
    "points",
    "row",
    "column",
    "col",
    "grid_row",
    "grid_column",
    "grid_col",
    "date",
}


POSITION_TOKENS = {"x", "y", "z", "lat", "lon", "easting", "northing", "map", "field"}
"""A column whose name has one of these words is a position, not a trait (e.g. ``map_x_m``)."""


def variable_of(column: str) -> Variable | None:
    """The variable of a plants.csv column, or None for an identifier or position column.
    Columns not known by name are variables when their name ends with a unit."""
    if column in KNOWN:
        return KNOWN[column]
    if column in NOT_TRAITS:
        return None
    match = re.fullmatch(r"(.+)_(m|cm|mm|cm2|deg|count)", column)
    if match is None or POSITION_TOKENS & set(match[1].split("_")):
        return None
    trait = match[1].replace("_", " ")
    return Variable(column, column, trait, f"{trait} (fieldapp reconstruct)", UNITS[match[2]])
