"""What every page is given: the settings, the device hub, the notifier and the UI state."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from fieldapp.settings import Settings, save_settings
from ui.devices.hub import DeviceHub
from ui.notifications import Notifier
from ui.state import UiState

log = logging.getLogger(__name__)


@dataclass
class AppContext:
    """Shared by the main window and its pages. ``settings_path`` is where device choices are
    saved (``None``: the user's settings file)."""

    settings: Settings
    hub: DeviceHub
    notifier: Notifier
    ui_state: UiState
    settings_path: Path | None = None

    def save_settings(self) -> None:
        """Write the settings; a failure is a notice, never a crash."""
        try:
            path = save_settings(self.settings, self.settings_path)
        except OSError as error:
            self.notifier.error("Settings not saved", error)
            return
        log.info("settings saved to %s", path)
