"""Every figure on the Live page is explained by a tooltip: the stream's counters
("dropped by the camera", "replaced before shown") and each capture-quality row ("crop
region"...)."""

from __future__ import annotations

from collections.abc import Callable

from devices.camera.quality import QualityReport, QualityThresholds
from ui.live.help import QUALITY_HELP, STREAM_HELP
from ui.live.preview import LivePreview, quality_rows

from .test_live import make_preview  # noqa: F401 - the fixture


def test_every_quality_row_has_help() -> None:
    report = QualityReport(0.9, 0.632, 0.01, 0.0, 0.1, 0.02)
    names = [name for name, _value, _ok in quality_rows(report, QualityThresholds())]
    assert sorted(names) == sorted(QUALITY_HELP)
    assert "crop radius" in QUALITY_HELP["crop region"]


def test_the_live_page_explains_its_figures(make_preview: Callable[[], LivePreview]) -> None:  # noqa: F811
    preview = make_preview()
    tip = preview.stream_label.toolTip()
    assert "dropped by the camera:" in tip and "replaced before shown:" in tip
    assert tip == STREAM_HELP
    preview.show_quality(QualityReport(0.9, 0.632, 0.01, 0.0, 0.1, 0.02), [])
    tips = {name.text(): name.toolTip() for name, _value in preview.quality_values}
    assert tips["crop region"] == QUALITY_HELP["crop region"]
    assert all(tips.values())
