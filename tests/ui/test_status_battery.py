"""The status bar shows the base's battery against the settings' levels, as missions judge it."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.settings import BatterySettings
from ui.status import StatusBar

pytestmark = pytest.mark.usefixtures("no_leaks")


def test_battery_turns_orange_at_the_warning_level_and_red_at_the_critical_one(
    tmp_path: Path,
) -> None:
    bar = StatusBar(tmp_path, BatterySettings(warn_pct=40.0, critical_pct=20.0))
    try:
        bar.set_battery(55.0)
        assert "55 %" in bar.battery.text() and "#" not in bar.battery.text()
        bar.set_battery(40.0)
        assert "#ef6c00" in bar.battery.text()
        bar.set_battery(20.0)
        assert "#c62828" in bar.battery.text() and "bold" in bar.battery.text()
        assert "stop at 20 %" in bar.battery.toolTip()
        bar.set_battery(None)
        assert bar.battery.text() == "Battery: -"
    finally:
        bar.deleteLater()
