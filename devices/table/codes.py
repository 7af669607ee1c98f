"""Grbl 1.1 error and alarm codes with their meanings (the firmware's published tables)."""

from __future__ import annotations

ERROR_MEANINGS: dict[int, str] = {
    1: "expected command letter: G-code words consist of a letter and a value",
    2: "bad number format: missing word value or invalid numeric format",
    3: "invalid statement: '$' system command not recognized or supported",
    4: "value < 0: negative value received for an expected positive value",
    5: "setting disabled: homing cycle is not enabled via settings",
    6: "value < 3 usec: minimum step pulse time must be greater than 3 usec",
    7: "EEPROM read fail: restoring affected EEPROM to default values",
    8: "not idle: '$' command cannot be used unless Grbl is IDLE",
    9: "G-code lock: G-code commands are locked out during alarm or jog state",
    10: "homing not enabled: soft limits cannot be enabled without homing",
    11: "line overflow: maximum characters per line exceeded, line not executed",
    12: "step rate > 30 kHz: setting value causes the step rate to exceed the maximum",
    13: "check door: safety door detected as opened and door state initiated",
    14: "line length exceeded: build info or startup line exceeds EEPROM line length",
    15: "travel exceeded: jog target exceeds machine travel, command ignored",
    16: "invalid jog command: jog command has no '=' or contains prohibited G-code",
    17: "setting disabled: laser mode requires PWM output",
    20: "unsupported command: unsupported or invalid G-code command found in block",
    21: "modal group violation: more than one G-code command from the same modal group",
    22: "undefined feed rate: feed rate has not yet been set or is undefined",
    23: "G-code command in block requires an integer value",
    24: "more than one G-code command that requires axis words found in block",
    25: "repeated G-code word found in block",
    26: "no axis words found in block for a command or modal state that requires them",
    27: "line number value is invalid",
    28: "G-code command is missing a required value word",
    29: "G59.x work coordinate systems are not supported",
    30: "G53 only allowed with G0 and G1 motion modes",
    31: "axis words found in block when no command or modal state uses them",
    32: "G2 and G3 arcs require at least one in-plane axis word",
    33: "motion command target is invalid",
    34: "arc radius value is invalid",
    35: "G2 and G3 arcs require at least one in-plane offset word",
    36: "unused value words found in block",
    37: "G43.1 dynamic tool length offset is not assigned to the configured axis",
    38: "tool number greater than maximum supported value",
}

ALARM_MEANINGS: dict[int, str] = {
    1: "hard limit triggered; machine position is likely lost, re-homing recommended",
    2: "soft limit: motion target exceeds machine travel; position retained",
    3: "reset while in motion; machine position is likely lost, re-homing recommended",
    4: "probe fail: probe not in the expected initial state",
    5: "probe fail: probe did not contact the workpiece within the programmed travel",
    6: "homing fail: the active homing cycle was reset",
    7: "homing fail: safety door was opened during the homing cycle",
    8: "homing fail: pull-off travel failed to clear the limit switch",
    9: "homing fail: could not find the limit switch within the search distance",
    10: "homing fail: dual-axis homing could not find the second limit switch",
}

CRITICAL_ALARMS = frozenset({1, 2})
"""Alarms after which Grbl ignores every line until a reset (Ctrl-X): hard and soft limits."""

POSITION_LOST_ALARMS = frozenset({1, 3, 6, 7, 8, 9, 10})
"""Alarms after which the machine position cannot be trusted any more."""


def error_meaning(code: int) -> str:
    """The meaning of ``error:code``; unknown codes are named as such."""
    return ERROR_MEANINGS.get(code, f"unknown error code {code}")


def alarm_meaning(code: int) -> str:
    """The meaning of ``ALARM:code``; unknown codes are named as such."""
    return ALARM_MEANINGS.get(code, f"unknown alarm code {code}")
