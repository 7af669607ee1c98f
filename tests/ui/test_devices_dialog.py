"""The device settings dialog: choices round-trip into DeviceSettings, present serial ports
are offered, and each connection test says what answered or what failed and why."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import shiboken6

from fieldapp.settings import DeviceSettings
from ui.devices.dialog import DeviceSettingsDialog
from ui.devices.probe import probe_base, probe_table
from ui.state import UiState

pytestmark = pytest.mark.usefixtures("no_leaks")

Wait = Callable[..., bool]


@pytest.fixture
def make_dialog(
    no_leaks: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Iterator[Callable[[DeviceSettings], DeviceSettingsDialog]]:
    monkeypatch.setattr(
        "ui.devices.dialog.list_serial_ports", lambda: [("/dev/ttyACM3", "Arduino Uno (Grbl)")]
    )
    dialogs: list[DeviceSettingsDialog] = []

    def make(devices: DeviceSettings) -> DeviceSettingsDialog:
        dialog = DeviceSettingsDialog(devices, UiState(tmp_path / "ui.ini"))
        dialog.show()
        dialogs.append(dialog)
        return dialog

    yield make
    for dialog in dialogs:
        dialog.reject()
        shiboken6.delete(dialog)


def test_choices_round_trip(make_dialog: Callable[[DeviceSettings], DeviceSettingsDialog]) -> None:
    devices = DeviceSettings(
        camera_backend="kinect2", table_port="/dev/ttyACM3", base_endpoint="tcp://10.0.0.2:5555",
        base_keys_dir=Path("/keys"), realtime_simulation=False,
    )  # fmt: skip
    dialog = make_dialog(devices)
    items = [dialog.table_port.itemText(i) for i in range(dialog.table_port.count())]
    assert items == ["Simulated", "/dev/ttyACM3 (Arduino Uno (Grbl))"]
    assert dialog.settings() == devices
    dialog.base_simulated.setChecked(True)
    assert not dialog.base_endpoint.isEnabled()
    dialog.table_port.setCurrentIndex(0)
    dialog.camera_backend.setCurrentIndex(dialog.camera_backend.findData("sim"))
    assert dialog.settings() == DeviceSettings(
        base_keys_dir=Path("/keys"), realtime_simulation=False
    )
    dialog.table_port.setEditText("socket://192.168.1.7:23")
    assert dialog.settings().table_port == "socket://192.168.1.7:23"


def test_a_port_not_present_is_kept(
    make_dialog: Callable[[DeviceSettings], DeviceSettingsDialog],
) -> None:
    dialog = make_dialog(DeviceSettings(table_port="/dev/ttyUSB9"))
    assert dialog.settings().table_port == "/dev/ttyUSB9"


def test_failed_tests_say_why(
    make_dialog: Callable[[DeviceSettings], DeviceSettingsDialog], wait_until: Wait
) -> None:
    dialog = make_dialog(DeviceSettings(table_port="/dev/ttyUSB-fieldapp-absent"))
    dialog.base_simulated.setChecked(False)
    dialog.base_endpoint.setText("tcp://192.0.2.10:5555")  # off loopback, without keys
    dialog.test("table")
    dialog.test("base")
    assert wait_until(lambda: not dialog.testing, 15.0)
    table, base = dialog.results["table"], dialog.results["base"]
    assert table.result is not None and not table.result.ok
    assert "TableDisconnected" in table.text() and "ttyUSB-fieldapp-absent" in table.text()
    assert "USB cable" in table.text()
    assert base.result is not None and not base.result.ok
    assert "InsecureEndpoint" in base.text() and "key folder" in base.text()


def test_simulated_devices_answer(
    make_dialog: Callable[[DeviceSettings], DeviceSettingsDialog], wait_until: Wait
) -> None:
    dialog = make_dialog(DeviceSettings())
    dialog.test_all()
    assert wait_until(lambda: not dialog.testing, 30.0)
    results = {name: label.result for name, label in dialog.results.items()}
    assert all(r is not None and r.ok for r in results.values()), results
    assert (
        "simulated Grbl" in dialog.results["table"].text()
        and "Idle" in dialog.results["table"].text()
    )
    assert "battery" in dialog.results["base"].text()
    assert "512 x 424" in dialog.results["camera"].text()


def test_probes_against_simulators() -> None:
    table = probe_table(None)
    assert table.ok and "at 0.000 deg" in table.message
    base = probe_base(None, Path("/nonexistent-keys"))
    assert not base.ok and "KeyFileError" in base.message
