"""The rig calibration file (``fieldapp-calibration/1``): models, loading and durable writing."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainSerializer,
    PlainValidator,
    StrictInt,
    field_validator,
    model_validator,
    with_config,
)
from typing_extensions import TypedDict

from devices.camera.frames import Intrinsics
from devices.geometry import make_transform
from fieldapp.io.durable import write_json_durably
from fieldapp.io.images import depth_units_to_m
from fieldapp.io.jsonfile import load_model, to_rigid_matrix

CALIBRATION_FORMAT = "fieldapp-calibration/1"

RigidMatrix = Annotated[
    NDArray[np.float64],
    PlainValidator(to_rigid_matrix),
    PlainSerializer(lambda m: np.asarray(m).tolist(), return_type=list),
]
"""A 4 x 4 rigid transform: nested lists in JSON, a float64 array in memory."""

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class SpecModel(BaseModel):
    """Base of the spec's objects: unknown fields are kept (readers ignore, writers may add)."""

    model_config = ConfigDict(extra="allow", arbitrary_types_allowed=True)


@with_config(ConfigDict(extra="allow"))
class Provenance(TypedDict, total=False):
    """Where a calibrated section came from (``calibrated``, ``refined_with_stations``): the
    date, the software, the rig's serial, the method, and the solver's quality figures as
    further keys (``rms_px``, ``rmse_mm``, ...), all kept when read and written back."""

    date: str
    software: str
    rig_serial: str
    method: str


class DepthCamera(SpecModel):
    width: StrictInt = Field(gt=0)
    height: StrictInt = Field(gt=0)
    fx: FiniteFloat = Field(gt=0)
    fy: FiniteFloat = Field(gt=0)
    cx: FiniteFloat
    cy: FiniteFloat
    distortion: list[FiniteFloat] = Field(default_factory=lambda: [0.0] * 5)
    depth_scale: FiniteFloat = Field(default=1000.0, gt=0)
    depth_offset_m: FiniteFloat | None = Field(default=None, ge=-0.2, le=0.2)
    """The unit's static depth offset (a field this project adds; readers ignore it): what
    it adds to every depth it measures, estimated from the boards by ``fieldapp calibrate
    views`` (``calib/depth_offset.py``) and taken off every depth read (:meth:`metres`)."""
    calibrated: Provenance | None = None

    @field_validator("distortion")
    @classmethod
    def _opencv_lengths(cls, value: list[float]) -> list[float]:
        if len(value) not in (4, 5, 8, 12, 14):
            raise ValueError("distortion must have 4, 5, 8, 12 or 14 entries (OpenCV order)")
        return value

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(
            width=self.width,
            height=self.height,
            fx=self.fx,
            fy=self.fy,
            cx=self.cx,
            cy=self.cy,
            distortion=tuple(self.distortion),
        )

    def metres(self, units: NDArray[np.uint16]) -> NDArray[np.float32]:
        """Stored depth units to metres (float32, NaN where none is measured), the unit's
        depth offset taken off."""
        depth_m = depth_units_to_m(units, self.depth_scale)
        if self.depth_offset_m:
            depth_m -= np.float32(self.depth_offset_m)
        return depth_m

    @classmethod
    def from_intrinsics(cls, intrinsics: Intrinsics, depth_scale: float = 1000.0) -> DepthCamera:
        return cls(
            width=intrinsics.width,
            height=intrinsics.height,
            fx=intrinsics.fx,
            fy=intrinsics.fy,
            cx=intrinsics.cx,
            cy=intrinsics.cy,
            distortion=list(intrinsics.distortion),
            depth_scale=depth_scale,
        )


def T_view0_view(T_view_next: NDArray[np.float64], view: int) -> NDArray[np.float64]:
    """Maps view ``view`` into view 0, given the step that maps view k+1 into view k: the
    paper's Eq. 9, p0 = R^j p_j + (R^(j-1) + ... + R + I) t."""
    if view < 0:
        raise ValueError(f"view must be >= 0, got {view}")
    R, t = T_view_next[:3, :3], T_view_next[:3, 3]
    R_power = np.eye(3)
    t_sum = np.zeros(3)
    for _ in range(view):
        t_sum = t_sum + R_power @ t
        R_power = R_power @ R
    return make_transform(R_power, t_sum)


class ViewStep(SpecModel):
    """``matrix`` maps view k+1 into view k at the same station (the table turned by angle)."""

    angle_deg: FiniteFloat
    matrix: RigidMatrix
    calibrated: Provenance | None = None
    refined_with_stations: Provenance | None = None
    nominal: str | Provenance | None = None
    """Where an uncalibrated step came from (an import, the turntable simulator): said so
    nobody mistakes it for a calibration; the turntable reconstruction refines such a step."""

    @field_validator("angle_deg")
    @classmethod
    def _divides_circle(cls, value: float) -> float:
        if not 0.0 < abs(value) <= 180.0:
            raise ValueError("angle_deg must be non-zero and at most 180 degrees")
        return value

    @property
    def views_per_turn(self) -> int:
        """How many views make a full turn (8 for 45 degrees)."""
        return max(1, round(360.0 / abs(self.angle_deg)))

    def T_view0_view(self, view: int) -> NDArray[np.float64]:
        """Maps view ``view`` into view 0 by applying ``matrix`` ``view`` times (paper, Eq. 9)."""
        return T_view0_view(self.matrix, view)


class StationPose(SpecModel):
    """Where the base stood at a station (map frame, metres, degrees), as it reported it."""

    x: FiniteFloat
    y: FiniteFloat
    yaw_deg: FiniteFloat


class Stations(SpecModel):
    """``to_reference[s]`` maps view 0 of station s into the reference frame. ``base_poses``
    (optional; fieldapp writes it when the calibration's captures carry ``base_pose``): where
    the base reported standing at each station while the boards were captured, so that a
    session's reported poses can move the stations from there (``fieldapp/recon/arrival.py``)."""

    reference: StrictInt
    to_reference: dict[int, RigidMatrix]
    base_poses: dict[int, StationPose] | None = None
    calibrated: Provenance | None = None

    @field_validator("to_reference", "base_poses", mode="before")
    @classmethod
    def _station_keys(cls, value: Any) -> Any:
        if isinstance(value, dict):
            for key in value:
                if isinstance(key, str) and not key.strip().isdigit():
                    raise ValueError(f"station key {key!r} is not a station number")
        return value

    @model_validator(mode="after")
    def _reference_listed(self) -> Stations:
        if self.reference not in self.to_reference:
            raise ValueError(f"reference station {self.reference} has no to_reference entry")
        return self


class Ground(SpecModel):
    """``matrix`` maps the reference frame into the field frame (z up, 0 on the ground)."""

    matrix: RigidMatrix
    calibrated: Provenance | None = None


class Calibration(SpecModel):
    """A ``fieldapp-calibration/1`` document. ``view_step`` and ``stations`` may be absent in a
    calibration that is still being built (intrinsics only); a session needs them."""

    format: Literal["fieldapp-calibration/1"]
    depth_camera: DepthCamera
    view_step: ViewStep | None = None
    stations: Stations | None = None
    ground: Ground | None = None

    def to_document(self) -> dict[str, Any]:
        document: dict[str, Any] = self.model_dump(mode="json", exclude_none=True)
        if self.stations is not None:  # JSON object keys are strings
            for key in ("to_reference", "base_poses"):
                if key in document["stations"]:
                    document["stations"][key] = {
                        str(k): v for k, v in document["stations"][key].items()
                    }
        return document


def load_calibration(path: Path) -> Calibration:
    """Read and validate a calibration file; raises :class:`~fieldapp.errors.FormatError`."""
    return load_model(path, Calibration)


def save_calibration(path: Path, calibration: Calibration) -> None:
    """Write a calibration file durably."""
    write_json_durably(path, calibration.to_document())


def nominal_views(calibration: Calibration) -> int:
    """Views per station implied by the calibration (8 when it does not say)."""
    if calibration.view_step is None:
        return 8
    return calibration.view_step.views_per_turn
