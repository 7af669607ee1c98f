"""Writing several files durably at once: renamed in order, none replaced when one fails."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldapp.io import durable


def _contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_files_are_written_into_their_folders_in_order(tmp_path, monkeypatch):
    files = {tmp_path / f"plants/{i}.ply": bytes([i]) * 1000 for i in range(1, 7)}
    files[tmp_path / "report.json"] = b"{}\n"
    renamed: list[str] = []
    replace = durable.os.replace

    def recording(source: Path, target: Path) -> None:
        renamed.append(Path(target).name)
        replace(source, target)

    monkeypatch.setattr(durable.os, "replace", recording)
    durable.write_files_durably(files)
    assert renamed == [p.name for p in files]
    assert _contents(tmp_path) == {str(p.relative_to(tmp_path)): d for p, d in files.items()}


def test_no_file_is_replaced_when_one_cannot_be_written(tmp_path, monkeypatch):
    old = {tmp_path / name: b"old" for name in ("a.ply", "b.ply", "c.ply")}
    durable.write_files_durably(old)
    synced = durable._synced_temporary

    def disk_full(path: Path, data: bytes) -> Path:
        if path.name == "b.ply":
            raise OSError(28, "No space left on device")
        return synced(path, data)

    monkeypatch.setattr(durable, "_synced_temporary", disk_full)
    with pytest.raises(OSError, match="No space"):
        durable.write_files_durably({path: b"new" for path in old})
    assert _contents(tmp_path) == {"a.ply": b"old", "b.ply": b"old", "c.ply": b"old"}


def test_a_crash_while_renaming_leaves_each_file_whole(tmp_path, monkeypatch):
    old = {tmp_path / name: b"old" for name in ("a.ply", "b.ply", "c.ply")}
    durable.write_files_durably(old)
    replace = durable.os.replace

    def crash_at_b(source: Path, target: Path) -> None:
        if Path(target).name == "b.ply":
            raise KeyboardInterrupt
        replace(source, target)

    monkeypatch.setattr(durable.os, "replace", crash_at_b)
    with pytest.raises(KeyboardInterrupt):
        durable.write_files_durably({path: b"new" for path in old})
    assert _contents(tmp_path) == {"a.ply": b"new", "b.ply": b"old", "c.ply": b"old"}
