"""Figures as PNG bytes, drawn with matplotlib's Agg canvas (no GUI, no global pyplot state,
so safe from any thread and free of Qt)."""

from __future__ import annotations

import datetime as dt
import io
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from fieldapp.evaluate.metrics import Agreement

DPI = 110
UNITS = {"height": "height (cm)", "width": "width (cm)"}


def _png(figure: Figure) -> bytes:
    FigureCanvasAgg(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI)
    return buffer.getvalue()


def trait_scatter_png(
    trait: str,
    algorithm: Sequence[float],
    reference: Sequence[float],
    result: Agreement,
    unit: str = "cm",
) -> bytes:
    """Algorithm against reference with the 1:1 line and the figures (paper, Figure 10);
    ``unit``: the trait's (organ traits are in cm, mm, cm², degrees or leaves)."""
    figure = Figure(figsize=(4.6, 4.4), layout="constrained")
    axes = figure.add_subplot()
    axes.scatter(reference, algorithm, s=22, color="tab:green", edgecolor="black", linewidth=0.4)
    values = [*algorithm, *reference] or [0.0, 1.0]
    low, high = min(values), max(values)
    pad = 0.05 * (high - low or 1.0)
    line = [low - pad, high + pad]
    axes.plot(line, line, color="black", linewidth=1.0, label="1:1")
    axes.set_xlim(line[0], line[1])
    axes.set_ylim(line[0], line[1])
    axes.set_aspect("equal")
    label = UNITS.get(trait, f"{trait} ({unit})")
    axes.set_xlabel(f"reference {label}")
    axes.set_ylabel(f"algorithm {label}")
    r2 = "n/a" if result.r2 is None else f"{result.r2:.3f}"
    rmse = "n/a" if result.rmse is None else f"{result.rmse:.2f} {unit}"
    axes.set_title(f"{trait}: n = {result.n}, R² = {r2}, RMSE = {rmse}", fontsize=10)
    axes.legend(loc="upper left")
    return _png(figure)


def distance_histogram_png(title: str, labels: Sequence[str], percents: Sequence[float]) -> bytes:
    """The share of points in each distance bin (paper, Figure 12)."""
    figure = Figure(figsize=(4.8, 3.4), layout="constrained")
    axes = figure.add_subplot()
    bars = axes.bar(labels, percents, color="tab:blue", edgecolor="black", linewidth=0.4)
    axes.bar_label(bars, labels=[f"{p:.1f}" for p in percents], fontsize=8)
    axes.set_xlabel("distance to the ideal sphere (cm)")
    axes.set_ylabel("points (%)")
    axes.set_ylim(0, max(100.0, *percents) * 1.08 if percents else 100.0)
    axes.set_title(title, fontsize=10)
    return _png(figure)


ONE_DATE_MARGIN_D = 3
"""Days shown either side of a single date (matplotlib would spread one date over years)."""
SPREAD_D = 0.3
"""Half-width, in days, over which one date's plants are spread so each point shows."""


def growth_figure(
    trait: str, series: Mapping[int, Sequence[tuple[dt.date, float]]], title: str
) -> Figure:
    """Points per plant (joined by a line over several dates) of ``trait`` against the date;
    dates as day labels, the legend outside the data. With one date, the plants are spread
    a little across that day (a strip) and the axis spans a week around it."""
    figure = Figure(figsize=(7.2, 4.0), layout="constrained")
    axes = figure.add_subplot()
    dates = sorted({d for points in series.values() for d, _ in points})
    plants = sorted(series)
    for index, plant in enumerate(plants):
        points = sorted(series[plant])
        days = np.array([d.toordinal() for d, _ in points], dtype=np.float64)
        if len(dates) == 1 and len(plants) > 1:
            days = days + SPREAD_D * (2.0 * index / (len(plants) - 1) - 1.0)
        style = "-o" if len(points) > 1 else "o"
        axes.plot(days, [v for _, v in points], style, markersize=4, label=f"{plant}")
    _date_axis(axes, dates)
    axes.set_ylabel(UNITS.get(trait, trait))
    count = f"{len(plants)} plant{'s' if len(plants) != 1 else ''} on {len(dates)} "
    count += "date" if len(dates) == 1 else "dates"
    axes.set_title(f"{title} ({count})", fontsize=10)
    axes.grid(alpha=0.3)
    if 0 < len(series) <= 24:
        axes.legend(
            title="plant", fontsize=7, ncols=1 + len(series) // 13,
            loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
        )  # fmt: skip
    return figure


def _date_axis(axes: Axes, dates: Sequence[dt.date]) -> None:
    """Day labels (``2026-05-14``) on an axis of day ordinals; one date gets a week around it."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    if not dates:
        return
    first, last = dates[0].toordinal(), dates[-1].toordinal()
    margin = ONE_DATE_MARGIN_D if first == last else max(1.0, 0.05 * (last - first))
    axes.set_xlim(first - margin, last + margin)
    axes.xaxis.set_major_locator(MaxNLocator(nbins=8, integer=True, min_n_ticks=1))
    if first == last:
        axes.set_xticks([first])
    axes.xaxis.set_major_formatter(
        FuncFormatter(lambda x, _pos: dt.date.fromordinal(round(x)).isoformat())
    )
    axes.set_xlabel("date")
    axes.tick_params(axis="x", labelrotation=30)


def growth_png(
    trait: str, series: Mapping[int, Sequence[tuple[dt.date, float]]], title: str
) -> bytes:
    """:func:`growth_figure` as PNG bytes."""
    return _png(growth_figure(trait, series, title))


def map_png(
    points_xy_m: NDArray[np.float64],
    colors: NDArray[np.uint8] | None,
    plants: Sequence[tuple[int, float, float]],
) -> bytes:
    """Top-down map: the cloud (x, y in the field frame) and each plant's base and id."""
    figure = Figure(figsize=(6.0, 6.0), layout="constrained")
    axes = figure.add_subplot()
    if len(points_xy_m):
        rgba = None if colors is None else colors.astype(np.float64) / 255.0
        axes.scatter(
            points_xy_m[:, 0],
            points_xy_m[:, 1],
            s=0.3,
            c=rgba if rgba is not None else "0.4",
            linewidths=0,
            rasterized=True,
        )
    for plant, x, y in plants:
        axes.plot(x, y, marker="+", color="red", markersize=9)
        axes.annotate(
            str(plant), (x, y), xytext=(4, 4), textcoords="offset points", color="red", fontsize=8
        )
    axes.set_aspect("equal")
    axes.set_xlabel("x (m, field frame)")
    axes.set_ylabel("y (m, field frame)")
    axes.set_title("top-down map", fontsize=10)
    return _png(figure)


def trait_bars_png(plants: Sequence[tuple[int, float, float]]) -> bytes:
    """Height and width of each plant (id, height_cm, width_cm) side by side."""
    figure = Figure(figsize=(6.4, 3.4), layout="constrained")
    axes = figure.add_subplot()
    ids = np.arange(len(plants))
    axes.bar(ids - 0.2, [p[1] for p in plants], width=0.4, label="height")
    axes.bar(ids + 0.2, [p[2] for p in plants], width=0.4, label="width")
    axes.set_xticks(ids, [str(p[0]) for p in plants])
    axes.set_xlabel("plant")
    axes.set_ylabel("cm")
    axes.legend()
    axes.set_title("plant traits", fontsize=10)
    return _png(figure)
