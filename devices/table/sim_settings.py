"""Grbl 1.1 settings of the simulated table controller (``$$``), with the table's values.

The table is axis X in degrees: ``$100`` steps per degree (200 steps x 16 microsteps x 180:1
worm / 360 degrees), ``$110`` maximum rate in deg/min, ``$120`` acceleration in deg/s^2.
"""

from __future__ import annotations

from collections.abc import Mapping

STEPS_PER_DEG = 200 * 16 * 180 / 360

DEFAULT_SETTINGS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0,
    10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0,
    30: 1000, 31: 0, 32: 0,
    100: STEPS_PER_DEG, 101: 250.0, 102: 250.0,
    110: 720.0, 111: 500.0, 112: 500.0,
    120: 30.0, 121: 10.0, 122: 10.0,
    130: 360.0, 131: 200.0, 132: 200.0,
}  # fmt: skip

INTEGER_SETTINGS = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32})


class SettingsError(ValueError):
    """A setting value a Grbl controller would refuse; ``code`` is its ``error:N``."""

    def __init__(self, code: int, text: str) -> None:
        self.code = code
        super().__init__(text)


def merged_settings(overrides: Mapping[int, float] | None) -> dict[int, float]:
    """The defaults with ``overrides`` applied, each checked like ``$N=V`` would be."""
    settings = dict(DEFAULT_SETTINGS)
    for number, value in (overrides or {}).items():
        check_setting(number, value)
        settings[number] = value
    return settings


def check_setting(number: int, value: float) -> None:
    """Raise :class:`SettingsError` with Grbl's code when ``$number=value`` is refused."""
    if number not in DEFAULT_SETTINGS:
        raise SettingsError(3, f"${number} is not a Grbl 1.1 setting")
    if value < 0:
        raise SettingsError(4, f"${number} must not be negative")
    if number in (100, 101, 102, 110, 111, 112, 120, 121, 122) and value <= 0:
        raise SettingsError(4, f"${number} must be positive")
