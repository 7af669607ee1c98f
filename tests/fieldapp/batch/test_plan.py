"""Planning on the client: ids and plots read from the folders, unusable folders rejected up
front, sessions done with the same settings hash and software version skipped."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from fieldapp.batch.plan import plan_batch, session_plot, task_settings
from fieldapp.io.session import load_session
from fieldapp.recon.settings import ReconstructionSettings
from fieldapp.results.db import ResultsDB
from fieldapp.results.sources import settings_hash

from .conftest import Sessions

SETTINGS = task_settings(ReconstructionSettings())


def with_document(source: Path, folder: Path, **fields: object) -> Path:
    """A copy of the session folder ``source`` with ``fields`` set in its session.json."""
    shutil.copytree(source, folder)
    document = json.loads((folder / "session.json").read_text()) | fields
    (folder / "session.json").write_text(json.dumps(document))
    return folder


def test_task_settings_are_plain_data_with_one_thread():
    settings = ReconstructionSettings(threads=4)
    data = task_settings(settings)
    assert data["threads"] == 1 and settings.threads == 4  # the caller's settings untouched
    assert json.loads(json.dumps(data)) == data
    assert ReconstructionSettings.model_validate(data) == settings.model_copy(update={"threads": 1})
    assert task_settings(settings, threads=3)["threads"] == 3


def test_plot_is_the_option_then_the_session_s_own_then_its_id(sessions, tmp_path):
    first = sessions.folders[0]
    session_id = load_session(first).id
    assert session_plot(first, None) == (session_id, session_id)
    assert session_plot(first, "north") == (session_id, "north")
    tagged = with_document(first, tmp_path / "tagged", plot="B-7")
    assert session_plot(tagged, None) == (session_id, "B-7")
    assert session_plot(tagged, "north") == (session_id, "north")


def test_unusable_folders_are_rejected_with_the_reason(sessions: Sessions, tmp_path: Path):
    first, second = sessions.folders[:2]
    twin = with_document(first, tmp_path / "twin")
    unsafe = with_document(second, tmp_path / "unsafe", id="../escape")
    missing = tmp_path / "missing"
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        plan = plan_batch([first, missing, twin, unsafe], SETTINGS, "1.0", db, tmp_path / "out")
    assert [i.session_dir for i in plan.to_run] == [first.resolve()]
    reasons = {r.session_dir.name: r.message for r in plan.rejected}
    assert set(reasons) == {"missing", "twin", "unsafe"}
    assert "no such folder" in reasons["missing"]
    assert str(first.resolve()) in reasons["twin"]
    assert "'../escape' cannot name a results folder" in reasons["unsafe"]


@pytest.mark.parametrize(
    ("settings", "version", "skipped"),
    [
        (SETTINGS, "1.0", True),
        (SETTINGS | {"threads": 2}, "1.0", False),
        (task_settings(ReconstructionSettings(crop={"radius_m": 2.0})), "1.0", False),
        (SETTINGS, "1.1", False),
    ],
)
def test_sessions_done_with_the_same_settings_and_version_are_skipped(
    sessions: Sessions, tmp_path: Path, settings, version, skipped
):
    first, second = sessions.folders[:2]
    with ResultsDB.open(tmp_path / "r.sqlite") as db:
        done = sessions.one_by_one[load_session(first).id]
        db.record_run("A", first, done, settings=SETTINGS, software_version="1.0")
        plan = plan_batch([first, second], settings, version, db, tmp_path / "out")
    assert plan.settings_sha256 == settings_hash(settings)
    assert [i.session_dir for i in plan.skipped] == ([first.resolve()] if skipped else [])
    expected = [second] if skipped else [first, second]
    assert [i.session_dir for i in plan.to_run] == [f.resolve() for f in expected]
