"""The calibration session folder remembered across the wizards (QSettings through
:class:`~ui.state.UiState`): chosen once for the view, station and ground wizards. Light on
purpose: the Calibrate overview reads it at start-up, before any solver is imported."""

from __future__ import annotations

from pathlib import Path

from ui.state import UiState

SESSION_KEY = "calibration/session_folder"


def remembered_session(ui_state: UiState | None) -> Path | None:
    """The calibration session folder used last, if it still exists."""
    if ui_state is None:
        return None
    text = ui_state.text(SESSION_KEY)
    return Path(text) if text and (Path(text) / "session.json").is_file() else None
