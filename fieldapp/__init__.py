"""fieldapp: Qt-free core of the field application for maize seedling phenotyping."""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    """``__version__``, looked up when first asked for: importing ``importlib.metadata`` and
    finding the installed distribution took 20 ms of every command's start-up (issue 22),
    and most commands never ask."""
    if name != "__version__":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        found = version("fieldapp")
    except PackageNotFoundError:  # running from a source tree that was not installed
        found = "0.0.0+source"
    globals()["__version__"] = found
    return found
