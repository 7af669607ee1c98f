"""The results panel's provenance line: one line of where the results came from, the details
(calibration file and sections, software, settings hash) in its tooltip."""

from __future__ import annotations

from typing import Any

from PySide6 import QtWidgets

from fieldapp.provenance import details_text, summary_line


def show_provenance(label: QtWidgets.QLabel, provenance: Any) -> None:
    """Show ``provenance`` (``report.json``'s, ``None`` for results written without it) on
    ``label``; simulated or unknown sources are drawn in the warning colour."""
    document = provenance if isinstance(provenance, dict) else None
    label.setText(summary_line(document))
    label.setToolTip(details_text(document))
    kind = ((document or {}).get("source") or {}).get("kind")
    label.setStyleSheet("" if kind in ("real", "imported") else "color: #a40;")
