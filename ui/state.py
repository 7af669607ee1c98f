"""What the window remembers between runs (QSettings): geometry, layout, the open page and
the last folders used for each kind of file."""

from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore

ORGANISATION = "fieldapp"
APPLICATION = "fieldapp-gui"


class UiState:
    """A thin typed layer over :class:`QtCore.QSettings`."""

    def __init__(self, path: Path | None = None) -> None:
        if path is None:
            self.qsettings = QtCore.QSettings(ORGANISATION, APPLICATION)
        else:
            self.qsettings = QtCore.QSettings(str(path), QtCore.QSettings.Format.IniFormat)

    def last_folder(self, kind: str, default: Path | None = None) -> Path:
        """The folder last used for ``kind`` (plans, sessions, frames...), if it still exists."""
        value = self.qsettings.value(f"folders/{kind}", "")
        folder = Path(str(value)) if value else None
        if folder is not None and folder.is_dir():
            return folder
        return default if default is not None else Path.home()

    def set_last_folder(self, kind: str, path: Path) -> None:
        folder = path if path.is_dir() else path.parent
        self.qsettings.setValue(f"folders/{kind}", str(folder))

    def value_bytes(self, key: str) -> QtCore.QByteArray | None:
        value = self.qsettings.value(key)
        return value if isinstance(value, QtCore.QByteArray) else None

    def set_value(self, key: str, value: object) -> None:
        self.qsettings.setValue(key, value)

    def text(self, key: str, default: str = "") -> str:
        value = self.qsettings.value(key, default)
        return str(value) if value is not None else default

    def sync(self) -> None:
        self.qsettings.sync()
