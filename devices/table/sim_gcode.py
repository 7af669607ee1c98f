"""The G-code subset of the simulated Grbl controller, with Grbl 1.1's error codes.

Supported: G0 G1 G4 G17 G20 G21 G53 G54 G90 G91 G94, M2 M3 M4 M5 M8 M9 M30, words F N P S T X
Y Z. Any other G or M code answers ``error:20`` (real Grbl would run some of them: G2/G3, G10,
G28, G38.x, G92...). Words are checked in Grbl's order: letter (1), number (2), unsupported code
(20), modal group (21), integer value (23), repeated word (25), negative value (4), missing
P for G4 (28), unused words (36).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

LINE_BUFFER_CHARS = 79
"""Grbl's line buffer holds 80 bytes with the terminator: 79 characters after cleaning."""

_G_GROUPS = {
    0: "motion",
    1: "motion",
    4: "non_modal",
    53: "non_modal",
    17: "plane",
    20: "units",
    21: "units",
    54: "coordinates",
    90: "distance",
    91: "distance",
    94: "feed_mode",
}
_M_GROUPS = {2: "stopping", 30: "stopping", 3: "spindle", 4: "spindle", 5: "spindle"}
_M_GROUPS |= {8: "coolant", 9: "coolant"}
_VALUE_LETTERS = "FNPSTXYZ"
_POSITIVE_LETTERS = "FNPST"
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)")


@dataclass
class GBlock:
    """One parsed line: the codes it names and its value words."""

    codes: dict[str, int] = field(default_factory=dict)
    words: dict[str, float] = field(default_factory=dict)

    @property
    def axis_words(self) -> dict[str, float]:
        return {k: v for k, v in self.words.items() if k in "XYZ"}


def clean_line(raw: bytes) -> tuple[str, bool]:
    """Grbl's line cleaning: drop spaces, control bytes, ``(comments)``, ``;`` tails, ``/``;
    upper-case. Returns the text and whether it overflowed the line buffer."""
    out: list[str] = []
    in_paren = False
    for byte in raw:
        ch = chr(byte)
        if in_paren:
            in_paren = ch != ")"
        elif ch == "(":
            in_paren = True
        elif ch == ";":
            break
        elif byte > 0x20 and ch != "/" and byte < 0x7F:
            out.append(ch.upper())
    return "".join(out[:LINE_BUFFER_CHARS]), len(out) > LINE_BUFFER_CHARS  # protocol.c: the 80th


def parse_block(text: str) -> GBlock | int:
    """Parse a cleaned G-code line; an ``int`` is the Grbl error code it answers."""
    block = GBlock()
    groups: set[str] = set()
    pos = 0
    while pos < len(text):
        letter = text[pos]
        if not "A" <= letter <= "Z":
            return 1
        match = _NUMBER.match(text, pos + 1)
        if match is None:
            return 2
        value = float(match.group())
        pos = match.end()
        error = _add_word(block, groups, letter, value)
        if error:
            return error
    return _check(block)


def _add_word(block: GBlock, groups: set[str], letter: str, value: float) -> int:
    if letter in "GM":
        table = _G_GROUPS if letter == "G" else _M_GROUPS
        group = table.get(int(value))
        if group is None:
            return 20
        if group in groups:
            return 21
        if value != int(value):
            return 23
        groups.add(group)
        block.codes[group] = int(value)
        return 0
    if letter not in _VALUE_LETTERS:
        return 20
    if letter in block.words:
        return 25
    if letter in _POSITIVE_LETTERS and value < 0:
        return 4
    block.words[letter] = value
    return 0


def _check(block: GBlock) -> GBlock | int:
    dwell = block.codes.get("non_modal") == 4
    if dwell and "P" not in block.words:
        return 28
    if "P" in block.words and not dwell:
        return 36
    if block.words.get("N", 0.0) > 9999999:
        return 27
    return block
