"""fieldapp: Qt-free core of the field application for maize seedling phenotyping."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("fieldapp")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+source"
