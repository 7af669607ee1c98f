"""Property-based tests: whatever is in the files, loaders either load or raise FormatError."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fieldapp.errors import FormatError
from fieldapp.io.calibration import load_calibration
from fieldapp.io.images import depth_m_to_units, depth_units_to_m
from fieldapp.io.session import load_session
from fieldapp.verify import verify_session

FIXTURE_OK = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=20,
)


def _paths(document: Any) -> list[tuple[Any, Any]]:
    """Every (container, key) in a JSON document."""
    found: list[tuple[Any, Any]] = []
    if isinstance(document, dict):
        for key, value in document.items():
            found.append((document, key))
            found += _paths(value)
    elif isinstance(document, list):
        for index, value in enumerate(document):
            found.append((document, index))
            found += _paths(value)
    return found


@FIXTURE_OK
@given(raw=st.binary(max_size=300))
def test_any_bytes_as_session_json(make_spec_session, raw):
    target = _session_folder(make_spec_session)
    (target / "session.json").write_bytes(raw)
    _load_or_format_error(target)


@FIXTURE_OK
@given(document=json_values)
def test_any_json_as_session_json(make_spec_session, document):
    target = _session_folder(make_spec_session)
    (target / "session.json").write_text(json.dumps(document))
    _load_or_format_error(target)


@FIXTURE_OK
@given(data=st.data(), replacement=json_values, which=st.sampled_from(["session", "calibration"]))
def test_any_single_field_changed(make_spec_session, data, replacement, which):
    target = _session_folder(make_spec_session)
    path = target / f"{which}.json"
    document = json.loads(path.read_text())
    container, key = data.draw(st.sampled_from(_paths(document)))
    container[key] = replacement
    path.write_text(json.dumps(document))
    _load_or_format_error(target)
    report = verify_session(target)  # must not raise either
    assert report.usable or report.problems


@FIXTURE_OK
@given(data=st.data())
def test_any_field_removed(make_spec_session, data):
    target = _session_folder(make_spec_session)
    document = json.loads((target / "calibration.json").read_text())
    dict_paths = [(c, k) for c, k in _paths(document) if isinstance(c, dict)]
    container, key = data.draw(st.sampled_from(dict_paths))
    del container[key]
    (target / "calibration.json").write_text(json.dumps(document))
    try:
        load_calibration(target / "calibration.json")
    except FormatError as error:
        assert error.problems
        assert all(str(target / "calibration.json") == p.file for p in error.problems)


@given(
    depth_m=arrays(
        np.float32,
        (5, 7),
        elements=st.floats(0.0, 70.0, width=32) | st.just(math.nan),
    ),
    depth_scale=st.sampled_from([1000.0, 4000.0]),
)
def test_depth_units_round_trip_within_half_a_unit(depth_m, depth_scale):
    units = depth_m_to_units(depth_m, depth_scale)
    back = depth_units_to_m(units, depth_scale)
    representable = np.isfinite(depth_m) & (np.rint(depth_m * depth_scale) >= 1)
    representable &= np.rint(depth_m * depth_scale) <= 65535
    assert np.all(np.isnan(back[~representable]))
    np.testing.assert_allclose(
        back[representable], depth_m[representable], atol=0.5 / depth_scale + 1e-5
    )


_FOLDERS: dict[int, Path] = {}


def _session_folder(factory: Any) -> Path:
    """One valid session per test function, its JSON files rewritten by each example."""
    key = id(factory)
    if key not in _FOLDERS:
        _FOLDERS.clear()
        _FOLDERS[key] = factory()
    folder = _FOLDERS[key]
    originals = folder / ".originals"
    if not originals.exists():
        originals.mkdir()
        for name in ("session.json", "calibration.json"):
            (originals / name).write_bytes((folder / name).read_bytes())
    for name in ("session.json", "calibration.json"):
        (folder / name).write_bytes((originals / name).read_bytes())
    return folder


def _load_or_format_error(folder: Path) -> None:
    try:
        load_session(folder)
    except FormatError as error:
        assert error.problems
        assert all(p.file and p.message for p in error.problems)
