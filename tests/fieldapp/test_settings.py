"""Settings: defaults, YAML file, FIELDAPP_* overrides, lenient fallback per bad field."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from fieldapp.settings import Settings, environment_overrides, load_settings, save_settings


def test_defaults_are_simulated_devices(tmp_path):
    settings = load_settings(tmp_path / "missing.yaml", environ={})
    assert settings.devices.camera_backend == "sim"
    assert settings.devices.table_port is None and settings.devices.base_endpoint is None


def test_file_then_environment(tmp_path):
    path = tmp_path / "settings.yaml"
    path.write_text("devices:\n  table_port: /dev/ttyUSB0\n  camera_backend: kinect2\n")
    settings = load_settings(path, environ={"FIELDAPP_DEVICES__CAMERA_BACKEND": "realsense"})
    assert settings.devices.table_port == "/dev/ttyUSB0"
    assert settings.devices.camera_backend == "realsense"


def test_partly_invalid_file_warns_per_field_and_keeps_the_rest(tmp_path, caplog):
    path = tmp_path / "settings.yaml"
    path.write_text(
        "devices:\n  table_port: /dev/ttyACM0\n  camera_backend: webcam\n"
        "  realtime_simulation: maybe\nunknown_section: 3\n"
    )
    with caplog.at_level(logging.WARNING, logger="fieldapp.settings"):
        settings = load_settings(path, environ={})
    assert settings.devices.table_port == "/dev/ttyACM0"
    assert settings.devices.camera_backend == "sim"
    assert settings.devices.realtime_simulation is True
    text = caplog.text
    assert "devices.camera_backend" in text
    assert "devices.realtime_simulation" in text
    assert "unknown_section" in text
    assert str(path) in text


@pytest.mark.parametrize(
    "content", ["devices: [1, 2\n", "- a list\n- not a mapping\n", "\xff\xfe garbage"]
)
def test_broken_file_never_blocks_start_up(tmp_path, caplog, content):
    path = tmp_path / "settings.yaml"
    path.write_bytes(content.encode("latin-1"))
    with caplog.at_level(logging.WARNING):
        settings = load_settings(path, environ={})
    assert settings == Settings()
    assert str(path) in caplog.text


def test_bad_environment_value_is_named(tmp_path, caplog):
    with caplog.at_level(logging.WARNING):
        settings = load_settings(tmp_path / "none.yaml", {"FIELDAPP_DEVICES__CAMERA_BACKEND": "x"})
    assert settings.devices.camera_backend == "sim"
    assert "devices.camera_backend" in caplog.text


def test_environment_parsing():
    values = environment_overrides(
        {"FIELDAPP_PATHS__RESULTS_DB": "/data/r.sqlite", "HOME": "/root", "FIELDAPP_SETTINGS": "x"}
    )
    assert values == {"paths": {"results_db": "/data/r.sqlite"}}


def test_the_tools_own_variables_are_not_taken_for_settings(tmp_path, caplog):
    """The start-up probe, the smoke test and the bundle's build switches start with
    FIELDAPP_ too; each was reported as an unknown setting (in the GUI, a notice)."""
    own = {f"FIELDAPP_{name}": "1" for name in ("STARTUP_PROBE", "SMOKE_TEST", "BUNDLE_SMOKE")}
    with caplog.at_level(logging.WARNING):
        settings = load_settings(tmp_path / "none.yaml", {**own, "FIELDAPP_BUNDLE_TRIM": "0"})
    assert settings == Settings() and caplog.text == ""
    with caplog.at_level(logging.WARNING):  # a typo is still said
        load_settings(tmp_path / "none.yaml", {"FIELDAPP_STARTUP_PROBES": "x"})
    assert "startup_probes" in caplog.text


def test_save_and_load_round_trip(tmp_path):
    settings = Settings()
    settings.devices.base_endpoint = "tcp://10.0.0.2:5555"
    path = save_settings(settings, tmp_path / "s.yaml")
    assert load_settings(path, environ={}) == settings


def test_settings_file_from_environment(tmp_path, monkeypatch):
    path = tmp_path / "elsewhere.yaml"
    path.write_text("devices:\n  base_endpoint: tcp://127.0.0.1:6000\n")
    monkeypatch.setenv("FIELDAPP_SETTINGS", str(path))
    assert load_settings().devices.base_endpoint == "tcp://127.0.0.1:6000"
    assert isinstance(Path(load_settings().paths.results_db), Path)


def test_camera_quality_settings_build_the_devices_thresholds(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("camera_quality:\n  min_fill_rate: 0.6\n")
    thresholds = load_settings(path, environ={}).camera_quality.thresholds()
    assert thresholds.min_fill_rate == 0.6
    assert thresholds.crop_radius_m == 2.25
