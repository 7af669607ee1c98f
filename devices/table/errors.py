"""Typed errors of the rotary table. Every message is meant for the operator."""

from __future__ import annotations


class TableException(Exception):
    """Base of every error the table driver raises on purpose."""


class TableTimeout(TableException):
    """The controller did not answer within the set bound."""


class TableDisconnected(TableException):
    """The serial port is gone (unplugged, closed) or could not be opened."""


class TableError(TableException):
    """The controller answered ``error:N``: it could not run the line."""

    def __init__(self, code: int, meaning: str, line: str = "") -> None:
        self.code = code
        self.meaning = meaning
        self.line = line
        sent = f" to {line!r}" if line else ""
        super().__init__(f"controller answered error:{code}{sent} ({meaning})")


class TableAlarm(TableException):
    """The controller is in Alarm (``ALARM:N``): it refuses to move until the operator acts."""

    def __init__(self, code: int | None, meaning: str, advice: str = "") -> None:
        self.code = code
        self.meaning = meaning
        label = f"ALARM:{code}" if code is not None else "Alarm state"
        text = f"table in alarm ({label}: {meaning})"
        super().__init__(f"{text}; {advice}" if advice else text)


class TablePositionUnknown(TableException):
    """The table's angle is not known (after a reset, an alarm that lost steps, an unplug):
    moves are refused until the operator homes the table or confirms its angle."""


class TableHeld(TableException):
    """A move was interrupted by a feed hold (``!``); it resumes only on ``~``."""


class TableMissedTarget(TableException):
    """The controller reported the move done but the read-back position is off target."""

    def __init__(self, target_deg: float, reached_deg: float, tolerance_deg: float) -> None:
        self.target_deg = target_deg
        self.reached_deg = reached_deg
        self.tolerance_deg = tolerance_deg
        super().__init__(
            f"table stopped at {reached_deg:.3f} deg, target {target_deg:.3f} deg "
            f"(tolerance {tolerance_deg:.3f} deg)"
        )


class TableMisconfigured(TableException):
    """The controller's settings do not suit the table (e.g. ``$13=1``, inches): nothing is
    moved until they are changed."""


class TableReset(TableException):
    """The controller was reset while a command was waiting for its answer."""
