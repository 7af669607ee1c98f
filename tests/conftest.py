"""Fixtures shared by every test folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository (``FIELDAPP_SHARED_DATA`` overrides it)."""
    folder = Path(os.environ.get("FIELDAPP_SHARED_DATA", REPO.parent / "shared" / "data"))
    if not folder.is_dir():
        pytest.fail(f"shared test data not found at {folder} (set FIELDAPP_SHARED_DATA)")
    return folder
