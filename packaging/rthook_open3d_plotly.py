"""PyInstaller runtime hook: open3d without its plotly viewer.

``open3d.visualization`` imports ``draw_plotly`` (plotly, dash, and through them IPython,
requests, werkzeug...) whenever ``open3d`` is imported. fieldapp never draws with plotly, and
the bundle leaves that stack out (about 130 MB; see packaging/README.md), so this hook puts a
module in its place whose functions say why they are missing.
"""

from __future__ import annotations

import sys
import types
from typing import NoReturn

MODULE = "open3d.visualization.draw_plotly"
FUNCTIONS = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")


class PlotlyViewerNotBundled(RuntimeError):
    """open3d's plotly viewer was called in the bundle, which leaves plotly out."""


def _not_bundled(name: str) -> NoReturn:
    raise PlotlyViewerNotBundled(
        f"open3d.visualization.{name} needs plotly and dash, which the fieldapp bundle leaves "
        "out; run it from a Python environment with plotly and dash installed"
    )


def _missing(name: str) -> types.FunctionType:
    def function(*_args: object, **_kwargs: object) -> NoReturn:
        _not_bundled(name)

    function.__name__ = function.__qualname__ = name
    return function  # type: ignore[return-value]


def install() -> None:
    module = types.ModuleType(MODULE, "open3d's plotly viewer, not in the fieldapp bundle")
    for name in FUNCTIONS:
        setattr(module, name, _missing(name))
    sys.modules.setdefault(MODULE, module)


install()
