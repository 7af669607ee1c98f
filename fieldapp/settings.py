"""Typed settings: a YAML file in the user's config folder, overridden by ``FIELDAPP_*`` variables.

``FIELDAPP_DEVICES__TABLE_PORT=/dev/ttyUSB0`` sets ``devices.table_port`` (``__`` separates
levels). A broken or partly invalid file never blocks start-up: each bad field is named in a
warning and falls back to its default.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import platformdirs
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

# pydantic imports this module lazily, at the first schema that needs it; two threads doing so at
# once (the GUI building pages while a worker builds models) can meet an import cycle inside
# pydantic and one gets a partially initialised module (ImportError, seen once in the packaged
# smoke test). Settings load first in every entry point, on the main thread: import it here.
import pydantic._internal._validators  # noqa: F401  isort: skip

from fieldapp.io.jsonfile import field_path
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.settings import ResultsSettings

if TYPE_CHECKING:
    from devices.camera.quality import QualityThresholds

log = logging.getLogger(__name__)

ENV_PREFIX = "FIELDAPP_"
SETTINGS_FILE_ENV = "FIELDAPP_SETTINGS"
NOT_SETTINGS = frozenset(
    {
        SETTINGS_FILE_ENV,
        "FIELDAPP_STARTUP_PROBE",  # ui/app.py: the start-up benchmark's probe file
        "FIELDAPP_SMOKE_TEST",  # packaging/entry.py: the bundle's smoke test
        "FIELDAPP_BUNDLE_SMOKE",  # packaging/build.sh: skip the built bundle's checks
        "FIELDAPP_BUNDLE_TRIM",  # packaging/build.sh and fieldapp.spec: the trimmed bundle
        "FIELDAPP_SHARED_DATA",  # the tests: where ../shared/data is
        "FIELDAPP_FUZZ_SEED",  # the tests: the file fuzzer's seed
        "FIELDAPP_FUZZ_CASES",  # the tests: the file fuzzer's case count
    }
)
"""``FIELDAPP_*`` variables that fieldapp's own tools read and that are not settings: never
taken for one (each used to be reported as an unknown setting, in the GUI as a notice)."""


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class DeviceSettings(Section):
    """Which devices to use. ``None`` for a port or endpoint means the simulated device."""

    camera_backend: Literal["sim", "replay", "kinect2", "realsense"] = "sim"
    replay_session: Path | None = None
    table_port: str | None = None
    base_endpoint: str | None = None
    base_keys_dir: Path | None = None
    realtime_simulation: bool = True


class PathSettings(Section):
    sessions_dir: Path = Field(
        default_factory=lambda: Path(platformdirs.user_data_dir("fieldapp")) / "sessions"
    )
    results_db: Path = Field(
        default_factory=lambda: Path(platformdirs.user_data_dir("fieldapp")) / "results.sqlite"
    )


class CameraQualitySettings(Section):
    """Go/no-go limits of a frame before a view is captured (``devices.camera.quality``)."""

    crop_radius_m: float = Field(default=2.25, gt=0)
    min_fill_rate: float = Field(default=0.85, ge=0, le=1)
    min_crop_fraction: float = Field(default=0.2, ge=0, le=1)
    max_flying_ratio: float = Field(default=0.03, ge=0, le=1)
    max_overexposed: float = Field(default=0.05, ge=0, le=1)
    max_underexposed: float = Field(default=0.20, ge=0, le=1)
    max_age_s: float = Field(default=0.5, gt=0)

    def thresholds(self) -> QualityThresholds:
        from devices.camera.quality import QualityThresholds

        return QualityThresholds(**self.model_dump())


class BatterySettings(Section):
    """The base's battery levels a mission checks before it starts and at every station.

    At or below ``warn_pct`` the operator is warned (once per station); at or below
    ``critical_pct`` a mission does not start, and a running one finishes the current view,
    saves it and stops."""

    warn_pct: float = Field(default=30.0, ge=0, le=100)
    critical_pct: float = Field(default=15.0, ge=0, le=100)

    @model_validator(mode="after")
    def _critical_below_warning(self) -> BatterySettings:
        if self.critical_pct > self.warn_pct:
            raise ValueError(
                f"critical_pct ({self.critical_pct:g}) must not be above warn_pct "
                f"({self.warn_pct:g})"
            )
        return self


class IncidentPolicy(Section):
    """What a mission does when the base loses its link or cannot reach a station
    (:mod:`fieldapp.mission.incidents`). The settings give new plans their policy; the plan
    carries it into every session folder."""

    lost_link: Literal["ask", "stop", "resume"] = "ask"
    """``ask`` the operator (resume / skip station / stop; stop when nobody can be asked),
    ``stop``, or ``resume`` by itself (at most ``retries.navigation`` times per station)."""
    blocked_path: Literal["ask", "stop", "skip"] = "ask"
    """After the navigation retries: ``ask`` the operator, ``stop``, or ``skip`` the station."""


class Settings(Section):
    devices: DeviceSettings = Field(default_factory=DeviceSettings)
    battery: BatterySettings = Field(default_factory=BatterySettings)
    paths: PathSettings = Field(default_factory=PathSettings)
    reconstruction: ReconstructionSettings = Field(default_factory=ReconstructionSettings)
    camera_quality: CameraQualitySettings = Field(default_factory=CameraQualitySettings)
    results: ResultsSettings = Field(default_factory=ResultsSettings)
    incidents: IncidentPolicy = Field(default_factory=IncidentPolicy)


def default_settings_path() -> Path:
    """``$FIELDAPP_SETTINGS`` or ``settings.yaml`` in the user's config folder."""
    override = os.environ.get(SETTINGS_FILE_ENV)
    if override:
        return Path(override)
    return Path(platformdirs.user_config_dir("fieldapp")) / "settings.yaml"


def environment_overrides(environ: Mapping[str, str]) -> dict[str, Any]:
    """Nested values from ``FIELDAPP_SECTION__FIELD`` variables (names lower-cased)."""
    values: dict[str, Any] = {}
    for name, value in environ.items():
        if not name.startswith(ENV_PREFIX) or name in NOT_SETTINGS:
            continue
        keys = name[len(ENV_PREFIX) :].lower().split("__")
        node = values
        for key in keys[:-1]:
            node = node.setdefault(key, {})
            if not isinstance(node, dict):
                break
        else:
            node[keys[-1]] = yaml.safe_load(value) if value else value
    return values


def _merge(base: dict[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for key, value in top.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def _drop(values: dict[str, Any], loc: tuple[int | str, ...]) -> bool:
    node: Any = values
    for key in loc[:-1]:
        if not isinstance(node, dict) or key not in node:
            return False
        node = node[key]
    if isinstance(node, dict) and loc and loc[-1] in node:
        del node[loc[-1]]
        return True
    return False


def validate_leniently(values: dict[str, Any], source: str) -> Settings:
    """Validate, dropping each bad field (with a warning naming it) until the rest is valid."""
    for _ in range(100):
        try:
            return Settings.model_validate(values)
        except ValidationError as error:
            dropped = False
            for problem in error.errors(include_url=False):
                loc = problem["loc"]
                while loc and not _drop(values, loc):
                    loc = loc[:-1]
                if loc:
                    dropped = True
                    log.warning(
                        "%s: %s: %s; using the default", source, field_path(loc), problem["msg"]
                    )
            if not dropped:
                break
    log.warning("%s: unusable; using the default settings", source)
    return Settings()


def read_settings_file(path: Path) -> dict[str, Any]:
    """The YAML mapping in ``path``, or ``{}`` (with a warning) when it is missing or broken."""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        log.warning("%s: cannot read settings (%s); using the defaults", path, error)
        return {}
    if data is None:
        return {}
    if not isinstance(data, dict):
        log.warning("%s: settings must be a mapping; using the defaults", path)
        return {}
    return data


def load_settings(path: Path | None = None, environ: Mapping[str, str] | None = None) -> Settings:
    """Settings from the file (default: :func:`default_settings_path`) and the environment."""
    path = path or default_settings_path()
    environ = os.environ if environ is None else environ
    values = _merge(read_settings_file(path), environment_overrides(environ))
    return validate_leniently(values, f"{path} (or {ENV_PREFIX}* variables)")


def save_settings(settings: Settings, path: Path | None = None) -> Path:
    """Write the settings as YAML (durably); returns the path written."""
    from fieldapp.io.durable import write_bytes_durably

    path = path or default_settings_path()
    text = yaml.safe_dump(settings.model_dump(mode="json"), sort_keys=False)
    write_bytes_durably(path, text.encode("utf-8"))
    return path
