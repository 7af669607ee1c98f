"""The results panel: open a session, reconstruct it in a worker, inspect the plants (3D view,
table, top-down map, registration quality, warnings), compare with manual measurements, follow
the plot's history and export everything. :class:`ResultsPanel` is the page's widget."""

from ui.results.panel import ResultsPanel

__all__ = ["ResultsPanel"]
