"""The udev rules: udev's syntax (checked by a small parser of the rules language, and by
``udevadm verify`` where systemd >= 253 has it), and what they do to each device they are for."""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

UDEV = Path(__file__).resolve().parents[2] / "packaging" / "udev"
KINECT = UDEV / "60-fieldapp-kinect2.rules"
SERIAL = UDEV / "61-fieldapp-serial.rules"

MATCH_KEYS = {"ACTION", "DEVPATH", "KERNEL", "KERNELS", "NAME", "SYMLINK", "SUBSYSTEM"}
MATCH_KEYS |= {"SUBSYSTEMS", "DRIVER", "DRIVERS", "ATTR", "ATTRS", "SYSCTL", "TAG", "TAGS"}
MATCH_KEYS |= {"ENV", "CONST", "TEST", "PROGRAM", "RESULT"}
ASSIGN_KEYS = {"NAME", "SYMLINK", "OWNER", "GROUP", "MODE", "SECLABEL", "ATTR", "SYSCTL", "ENV"}
ASSIGN_KEYS |= {"TAG", "RUN", "LABEL", "GOTO", "IMPORT", "OPTIONS"}
WITH_ATTRIBUTE = {"ATTR", "ATTRS", "SYSCTL", "ENV", "CONST", "TEST", "SECLABEL", "RUN", "IMPORT"}
TOKEN = re.compile(r'^([A-Z]+)(?:\{([^{}]+)\})?(==|!=|\+=|-=|:=|=)"([^"]*)"$')


@dataclass(frozen=True)
class Token:
    key: str
    attribute: str | None
    operator: str
    value: str

    @property
    def is_match(self) -> bool:
        return self.operator in ("==", "!=")


class RuleSyntaxError(ValueError):
    pass


def split_tokens(line: str) -> list[str]:
    """A rule line's comma-separated ``KEY{attr}OP"value"`` pairs (commas inside quotes kept)."""
    parts, current, quoted = [], "", False
    for char in line:
        if char == '"':
            quoted = not quoted
        if char == "," and not quoted:
            parts.append(current.strip())
            current = ""
        else:
            current += char
    if quoted:
        raise RuleSyntaxError(f"unterminated quote in {line!r}")
    parts.append(current.strip())
    return parts


def parse_token(text: str) -> Token:
    found = TOKEN.match(text)
    if found is None:
        raise RuleSyntaxError(f'not KEY=="value" or KEY="value": {text!r}')
    token = Token(*found.groups())
    known = MATCH_KEYS if token.is_match else ASSIGN_KEYS
    if token.key not in known:
        kind = "match" if token.is_match else "assignment"
        raise RuleSyntaxError(f"{token.key} is not a udev {kind} key ({text!r})")
    if (token.attribute is not None) != (token.key in WITH_ATTRIBUTE):
        raise RuleSyntaxError(f"{token.key} takes {{attribute}} only where udev allows: {text!r}")
    if token.key == "ATTRS" and not token.is_match:
        raise RuleSyntaxError(f"ATTRS can only be matched: {text!r}")
    if token.key == "MODE" and not re.fullmatch(r"0[0-7]{3}", token.value):
        raise RuleSyntaxError(f"MODE must be four octal digits: {text!r}")
    return token


def parse_rules(text: str) -> list[list[Token]]:
    """The rules of a rules file; raises :class:`RuleSyntaxError` naming the bad line."""
    rules = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if line.rstrip().endswith("\\"):
            raise RuleSyntaxError(f"line {number}: continued lines are not used here")
        try:
            tokens = [parse_token(part) for part in split_tokens(line)]
        except RuleSyntaxError as error:
            raise RuleSyntaxError(f"line {number}: {error}") from None
        if not any(t.is_match for t in tokens) or all(t.is_match for t in tokens):
            raise RuleSyntaxError(f"line {number}: a rule needs matches and assignments")
        rules.append(tokens)
    return rules


def applied(rules: list[list[Token]], device: dict[str, str]) -> dict[str, set[str]]:
    """What the matching rules assign to ``device`` (keys ``SUBSYSTEM``, ``idVendor``...)."""
    result: dict[str, set[str]] = {}
    for rule in rules:
        matches = [t for t in rule if t.is_match]
        if all(
            (device.get(t.attribute or t.key) == t.value) == (t.operator == "==") for t in matches
        ):
            for t in rule:
                if not t.is_match:
                    result.setdefault(
                        f"{t.key}{{{t.attribute}}}" if t.attribute else t.key, set()
                    ).add(t.value)
    return result


@pytest.mark.parametrize("path", [KINECT, SERIAL], ids=lambda p: p.name)
def test_rules_files_parse(path: Path) -> None:
    assert parse_rules(path.read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    "line",
    [
        'KERNEL="ttyUSB*", MODE="0660"',  # KERNEL can only be matched
        'SUBSYSTEM=="usb", GRUOP="plugdev"',  # unknown key
        'SUBSYSTEM=="usb", MODE="660"',  # not octal with a leading 0
        'SUBSYSTEM=="usb", ATTR{idVendor}=="045e, MODE="0660"',  # unterminated quote
        'SUBSYSTEM=="usb", ATTR{idVendor}=="045e"',  # matches only
        'SUBSYSTEM=="tty", ATTRS{idVendor}=="1a86", ATTRS{serial}="x"',  # ATTRS assigned
    ],
)
def test_the_parser_rejects_broken_rules(line: str) -> None:
    with pytest.raises(RuleSyntaxError):
        parse_rules(line)


@pytest.mark.parametrize("product", ["02c4", "02d8", "02d9"])
def test_every_kinect_v2_is_given_to_plugdev_and_the_seat_user(product: str) -> None:
    rules = parse_rules(KINECT.read_text(encoding="utf-8"))
    kinect = {"SUBSYSTEM": "usb", "idVendor": "045e", "idProduct": product}
    assert applied(rules, kinect) == {
        "MODE": {"0660"},
        "GROUP": {"plugdev"},
        "TAG": {"uaccess"},
    }


def test_other_microsoft_devices_are_left_alone() -> None:
    rules = parse_rules(KINECT.read_text(encoding="utf-8"))
    mouse = {"SUBSYSTEM": "usb", "idVendor": "045e", "idProduct": "0040"}
    assert applied(rules, mouse) == {}
    assert applied(rules, {"SUBSYSTEM": "tty", "idVendor": "045e", "idProduct": "02c4"}) == {}


@pytest.mark.parametrize(
    ("vendor", "product"),
    [("1a86", "7523"), ("0403", "6001"), ("2341", "0043"), ("2341", "0001"), ("10c4", "ea60")],
)
def test_serial_controllers_get_dialout_and_the_table_symlink(vendor: str, product: str) -> None:
    rules = parse_rules(SERIAL.read_text(encoding="utf-8"))
    port = {"SUBSYSTEM": "tty", "idVendor": vendor, "idProduct": product}
    assert applied(rules, port) == {
        "MODE": {"0660"},
        "GROUP": {"dialout"},
        "ENV{ID_MM_DEVICE_IGNORE}": {"1"},
        "SYMLINK": {"fieldapp-table"},
    }
    assert applied(rules, {**port, "SUBSYSTEM": "usb"}) == {}  # the tty, not the USB device


def test_other_serial_chips_get_no_symlink() -> None:
    rules = parse_rules(SERIAL.read_text(encoding="utf-8"))
    assert applied(rules, {"SUBSYSTEM": "tty", "idVendor": "0403", "idProduct": "6015"}) == {}


def test_symlink_is_added_not_replacing_others() -> None:
    tokens = [t for rule in parse_rules(SERIAL.read_text(encoding="utf-8")) for t in rule]
    assert {t.operator for t in tokens if t.key == "SYMLINK"} == {"+="}
    assert {t.operator for t in tokens if t.key == "TAG"} <= {"+="}


def test_rule_files_sort_before_the_seat_rules() -> None:
    """uaccess is acted on by 73-seat-late.rules: the tag must be set by an earlier file."""
    assert KINECT.name < "73-seat-late.rules"


def _udevadm_has_verify() -> bool:
    udevadm = shutil.which("udevadm")
    if udevadm is None:
        return False
    probe = subprocess.run([udevadm, "verify", "--help"], capture_output=True, timeout=10)
    return probe.returncode == 0


@pytest.mark.skipif(not _udevadm_has_verify(), reason="udevadm verify needs systemd >= 253")
def test_udevadm_verify_accepts_the_rules() -> None:
    done = subprocess.run(
        ["udevadm", "verify", str(KINECT), str(SERIAL)], capture_output=True, text=True, timeout=30
    )
    assert done.returncode == 0, done.stdout + done.stderr
