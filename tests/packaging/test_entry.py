"""packaging/entry.py: the bundle's command line (gui by default, every subcommand, the smoke
test by option or environment variable)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

ENTRY = Path(__file__).resolve().parents[2] / "packaging" / "entry.py"


@pytest.fixture(scope="module")
def entry() -> ModuleType:
    spec = importlib.util.spec_from_file_location("fieldapp_bundle_entry", ENTRY)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_smoke_test_switch_is_not_taken_for_a_setting(entry: ModuleType) -> None:
    from fieldapp.settings import NOT_SETTINGS

    assert entry.SMOKE_ENV in NOT_SETTINGS


def test_no_arguments_open_the_gui(entry: ModuleType) -> None:
    assert entry.cli_arguments([]) == ["gui"]
    assert entry.cli_arguments(["simulate", "--out", "x"]) == ["simulate", "--out", "x"]


@pytest.mark.parametrize(
    ("argv", "environ", "smoke"),
    [
        (["--smoke-test"], {}, True),
        (["--smoke-test", "--timeout-s", "5"], {}, True),
        ([], {"FIELDAPP_SMOKE_TEST": "1"}, True),
        ([], {"FIELDAPP_SMOKE_TEST": "yes"}, True),
        ([], {"FIELDAPP_SMOKE_TEST": "0"}, False),
        (["gui", "--smoke-test"], {}, False),  # only as the first argument
        ([], {}, False),
    ],
)
def test_smoke_test_is_asked_by_option_or_variable(
    entry: ModuleType, argv: list[str], environ: dict[str, str], smoke: bool
) -> None:
    assert entry.wants_smoke_test(argv, environ) is smoke


def test_smoke_variable_is_removed_before_the_settings_see_it(
    entry: ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[list[str]] = []

    def smoke_main(argv: list[str]) -> int:
        seen.append(list(argv))
        return 0

    monkeypatch.setattr("ui.smoke.main", smoke_main)
    environ = {"FIELDAPP_SMOKE_TEST": "1", "FIELDAPP_DEVICES__TABLE_PORT": "/dev/x"}
    assert entry.main(["--timeout-s", "9"], environ) == 0
    assert seen == [["--timeout-s", "9"]]
    assert environ == {"FIELDAPP_DEVICES__TABLE_PORT": "/dev/x"}


def test_other_arguments_run_the_fieldapp_command_line(
    entry: ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[list[str]] = []

    def cli_main(argv: list[str]) -> int:
        seen.append(list(argv))
        return 3

    monkeypatch.setattr("fieldapp.cli.main", cli_main)
    assert entry.main([], {}) == 3
    assert entry.main(["verify", "s"], {}) == 3
    assert seen == [["gui"], ["verify", "s"]]


def test_entry_script_lists_every_subcommand_including_the_gui() -> None:
    done = subprocess.run(
        [sys.executable, str(ENTRY), "--help"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    for command in ("gui", "simulate", "reconstruct", "calibrate", "mission", "batch"):
        assert f"    {command} " in done.stdout, command
