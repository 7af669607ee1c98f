"""The bundle's entry point (PyInstaller runs this file as ``__main__``).

* ``fieldapp ARGS...`` runs the ``fieldapp`` command line, every subcommand included;
* ``fieldapp`` with no argument (the desktop menu) opens the GUI (``fieldapp gui``);
* ``fieldapp --smoke-test [OPTIONS]``, or ``FIELDAPP_SMOKE_TEST=1 fieldapp``, runs the bundle's
  self-test (:mod:`ui.smoke`): the main window on simulated devices, offscreen, and a tiny
  simulated reconstruction; exit 0 when it passed.

The same file runs from a source tree: ``.venv/bin/python packaging/entry.py --smoke-test``.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from collections.abc import Mapping, MutableMapping, Sequence

SMOKE_FLAG = "--smoke-test"
SMOKE_ENV = "FIELDAPP_SMOKE_TEST"
DEFAULT_COMMAND = ("gui",)
_TRUE = {"1", "true", "yes", "on"}


def wants_smoke_test(argv: Sequence[str], environ: Mapping[str, str]) -> bool:
    """True when the first argument is ``--smoke-test`` or ``FIELDAPP_SMOKE_TEST`` is set."""
    if argv and argv[0] == SMOKE_FLAG:
        return True
    return environ.get(SMOKE_ENV, "").strip().lower() in _TRUE


def cli_arguments(argv: Sequence[str]) -> list[str]:
    """The ``fieldapp`` command line to run: ``gui`` when started without arguments."""
    return list(argv) if argv else list(DEFAULT_COMMAND)


def smoke_arguments(argv: Sequence[str]) -> list[str]:
    """The smoke test's own options (``--smoke-test`` itself removed)."""
    return list(argv[1:]) if argv and argv[0] == SMOKE_FLAG else list(argv)


def main(argv: Sequence[str] | None = None, environ: MutableMapping[str, str] | None = None) -> int:
    """Run the smoke test or the command line; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    environ = os.environ if environ is None else environ
    if wants_smoke_test(argv, environ):
        # FIELDAPP_* variables are settings overrides: this one is not a setting.
        environ.pop(SMOKE_ENV, None)
        from ui.smoke import main as smoke_main

        return smoke_main(smoke_arguments(argv))
    from fieldapp.cli import main as cli_main

    return cli_main(cli_arguments(argv))


if __name__ == "__main__":
    multiprocessing.freeze_support()  # dask's local cluster starts worker processes
    sys.exit(main())
