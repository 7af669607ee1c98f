"""``fieldapp results``, ``history`` and ``report`` as a user runs them."""

from __future__ import annotations

import csv
import datetime as dt

import numpy as np
import pytest

from fieldapp.cli import main

from .helpers import grid_plants, write_results


def test_add_list_history_and_report(tmp_path, capsys):
    db = str(tmp_path / "r.sqlite")
    bases = grid_plants(2)
    for day, date in enumerate(("2022-06-01", "2022-06-06", "2022-06-11")):
        order = np.roll(np.arange(16), day * 5)  # listed in another order each date
        rows = [(i + 1, *bases[k], 10.0 + 3 * day + k, 5.0 + k) for i, k in enumerate(order)]
        folder = write_results(tmp_path / f"d{day}", f"s{day}", rows)
        args = ["results", "--db", db, "add", str(folder), "--plot", "A", "--date", date]
        assert main(args) == 0
    assert "run 3: s2 (2022-06-11) of plot A, 16 plants" in capsys.readouterr().out
    assert main(["results", "--db", db, "list"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 4
    out_csv, figures = tmp_path / "h.csv", tmp_path / "fig"
    assert main(["history", "A", "--db", db, "--csv", str(out_csv), "--figures", str(figures)]) == 0
    assert "16 plants on 3 dates" in capsys.readouterr().out
    rows = list(csv.DictReader(out_csv.read_text(encoding="utf-8").splitlines()))
    assert len(rows) == 48
    for plant in {r["plant"] for r in rows}:
        heights = [float(r["height_cm"]) for r in rows if r["plant"] == plant]
        assert list(np.diff(heights)) == pytest.approx([3.0, 3.0])  # one growth curve per plant
    assert (figures / "growth_height.png").read_bytes()[:4] == b"\x89PNG"
    report = tmp_path / "report.html"
    assert main(["report", str(tmp_path / "d2"), "--out", str(report), "--db", db]) == 0
    html = report.read_text(encoding="utf-8")
    assert html.count("data:image/png;base64,") == 2  # map (empty cloud) and traits
    assert "cloud.ply: file is missing" in html
    assert "<td>16</td>" in html


def test_bad_arguments_exit_1_with_a_message(tmp_path, capsys):
    db = str(tmp_path / "r.sqlite")
    folder = write_results(tmp_path / "d", "s", [(1, 0.0, 0.0, 1.0, 1.0)])
    assert main(["results", "--db", db, "add", str(folder), "--plot", "A", "--date", "June"]) == 1
    assert "--date: 'June' is not a date" in capsys.readouterr().err
    assert main(["history", "A", "--db", db]) == 1
    assert "no results database" in capsys.readouterr().err
    assert main(["results", "--db", db, "add", str(folder), "--plot", "A"]) == 1
    assert "give the date" in capsys.readouterr().err
    assert (
        main(
            [
                "results",
                "--db",
                db,
                "add",
                str(folder),
                "--plot",
                "A",
                "--date",
                str(dt.date(2022, 1, 1)),
            ]
        )
        == 0
    )
    assert main(["history", "B", "--db", db]) == 1
    assert "no plot named 'B'" in capsys.readouterr().err
