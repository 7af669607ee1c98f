"""Typed errors of the core. Bad input is reported as :class:`Problem` lines (file, field)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Problem:
    """One thing wrong with an input: which file, which field, what is wrong."""

    file: str
    field: str
    message: str

    def __str__(self) -> str:
        where = f"{self.file}: {self.field}" if self.field else self.file
        return f"{where}: {self.message}"


class FieldappError(Exception):
    """Base of every error the core raises on purpose; its text is meant for the operator."""


class FormatError(FieldappError):
    """A session or calibration file does not follow the spec; ``problems`` says where."""

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))
