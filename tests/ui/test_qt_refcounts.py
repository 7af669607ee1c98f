"""Regression test for the Qt binding itself: PySide6-Essentials 6.12.0 on Python 3.11 drops one
reference to ``True`` on every ``Signal.emit()`` and one to ``None`` on every
``QGraphicsItem.update()``, until the interpreter aborts with ``Fatal Python error:
bool_dealloc`` minutes into a session (or at exit). The lock and pyproject.toml exclude that
release; this test keeps any future upgrade from bringing the leak back.

It runs in a child process, because a leaking binding may abort the interpreter outright.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

CALLS = 300  # enough to see a per-call leak, too few to exhaust True's references on 3.11

_CHILD = textwrap.dedent(
    f"""
    import json, sys
    from PySide6 import QtCore, QtWidgets

    app = QtWidgets.QApplication([])

    class Emitter(QtCore.QObject):
        fired = QtCore.Signal()
        valued = QtCore.Signal(int)

    emitter = Emitter()
    emitter.fired.connect(lambda: None)
    emitter.valued.connect(lambda value: None)
    scene = QtWidgets.QGraphicsScene()
    item = QtWidgets.QGraphicsRectItem(0, 0, 10, 10)
    scene.addItem(item)

    def drift(obj, call):
        call()  # warm-up: first calls may cache objects
        before = sys.getrefcount(obj)
        for _ in range({CALLS}):
            call()
        return sys.getrefcount(obj) - before

    print(json.dumps({{
        "emit_true": drift(True, emitter.fired.emit),
        "emit_value_true": drift(True, lambda: emitter.valued.emit(1)),
        "update_none": drift(None, item.update),
        "set_pos_none": drift(None, lambda: item.setPos(1.0, 2.0)),
    }}))
    """
)


@pytest.mark.skipif(
    sys.version_info >= (3, 12),
    reason="True and None are immortal from Python 3.12: a leak of them cannot abort there",
)
def test_signal_emit_and_item_update_keep_refcounts_of_true_and_none() -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    child = subprocess.run(
        [sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, timeout=60
    )
    assert child.returncode == 0, f"the Qt binding aborted the interpreter:\n{child.stderr}"
    drifts = json.loads(child.stdout.strip().splitlines()[-1])
    # A few references may move with caches; a per-call leak moves them by about CALLS.
    leaking = {name: d for name, d in drifts.items() if abs(d) > CALLS // 10}
    assert not leaking, f"reference counts drift per call ({CALLS} calls): {leaking}"
