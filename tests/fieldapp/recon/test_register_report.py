"""Each station's verdict and uncertainty reach report.json and the HTML report."""

from __future__ import annotations

import numpy as np

from fieldapp.evaluate.report import registration_section
from fieldapp.recon.register import StationRegistration
from fieldapp.recon.result import _station_entry


def test_report_entries_carry_the_verdict_uncertainty_and_limit() -> None:
    registration = StationRegistration(
        3,
        np.eye(4),
        np.eye(4),
        verdict="unreliable",
        uncertainty_m=0.0123,
        uncertainty_deg=0.45,
        limit_m=0.25,
        limit_deg=8.5,
        message="refined on 2 overlaps, but the estimated uncertainty is too large",
    )
    entry = _station_entry(registration)
    assert entry["verdict"] == "unreliable"
    assert entry["uncertainty_mm"] == 12.3 and entry["uncertainty_deg"] == 0.45
    assert entry["correction_limit_mm"] == 250.0 and entry["correction_limit_deg"] == 8.5


def test_the_html_report_warns_about_unreliable_stations() -> None:
    good = {"verdict": "refined", "uncertainty_mm": 2.6, "uncertainty_deg": 0.11}
    bad = {"verdict": "unreliable", "uncertainty_mm": 14.0, "uncertainty_deg": 0.5}
    html = registration_section({"stations": {"1": good, "7": bad}})
    assert "Unreliable registration: station 7" in html
    assert "2.6 / 0.11" in html and "unreliable" in html
    assert "Unreliable" not in registration_section({"stations": {"1": good}})
