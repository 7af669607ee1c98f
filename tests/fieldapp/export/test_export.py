"""``fieldapp export``: LAZ 1.4 and PLY with per-point plant, organ, leaf and mixed-pixel
fields, CSVs with units, BrAPI v2
JSON, a MIAPPE ISA-Tab bundle (checked structurally: the ISA tools do not install here)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest

from fieldapp.cli import main
from fieldapp.errors import FieldappError
from fieldapp.export.clouds import labelled_cloud
from fieldapp.recon.cloud import Cloud
from fieldapp.recon.organs import ORGAN_LEAF, ORGAN_STEM
from fieldapp.recon.outputs import LeafRow, PlantRow, PointLabels, write_outputs

EXPORTED_VERTEX = np.dtype(
    [("xyz", "<f4", 3), ("rgb", "u1", 3), ("plant_id", "<u4"), ("organ", "u1"),
     ("leaf_id", "u1"), ("mixed", "u1")]
)  # fmt: skip
"""A vertex of the exported ``cloud.ply`` (its ``scalar_`` fields by their plain names)."""
PLANTS = {1: (0.5, 1.0, 21.5, 12.25), 2: (1.25, 1.0, 18.0, 10.5), 3: (2.0, 1.1, 25.75, 14.0)}
"""plant -> x_m, y_m, height_cm, width_cm."""


def results_folder(
    folder: Path, seed: int, grid: bool = False, scale: float = 1.0, organs: bool = False
) -> Path:
    """A results folder as `fieldapp reconstruct` writes it: three plants of 400 points each
    and 300 points that belong to no plant; with ``grid``, row and column columns too; with
    ``organs``, as a run that measured organs and looked for mixed pixels writes it: per-point
    labels in ``cloud.ply`` (each plant's first 100 points stem, the rest two leaves) and a
    mixed flag on every tenth point."""
    rng = np.random.default_rng(seed)
    clouds = {
        p: Cloud(rng.normal([x, y, 0.1], 0.03, (400, 3)), rng.integers(0, 255, (400, 3), np.uint8))
        for p, (x, y, _, _) in PLANTS.items()
    }
    loose = Cloud(rng.uniform(0, 2.5, (300, 3)), np.zeros((300, 3), np.uint8))
    whole = Cloud.concatenate([*clouds.values(), loose])
    order = rng.permutation(len(whole))
    rows = [PlantRow(p, x, y, h * scale, w * scale, 400) for p, (x, y, h, w) in PLANTS.items()]
    report = {"format": "x", "session": f"{folder.name}-session", "warnings": []}
    labels, leaves = None, None
    if organs:
        leaves = [
            LeafRow(p, leaf, 30.0 * scale + leaf, 5.5, 120.0 + p, 40.0, 90.0 * leaf, 10.0 * leaf)
            for p in PLANTS
            for leaf in (1, 2)
        ]
        plant = np.repeat([*PLANTS, 0], [400, 400, 400, 300]).astype(np.int32)
        within = np.concatenate([np.arange(400)] * 3 + [np.zeros(300, np.intp)])
        organ = np.where(plant == 0, 0, np.where(within < 100, ORGAN_STEM, ORGAN_LEAF))
        leaf = np.where(organ == ORGAN_LEAF, 1 + (within >= 250), 0)
        labels = PointLabels(
            plant[order], organ[order].astype(np.uint8), leaf[order].astype(np.uint8)
        )
        whole = Cloud(whole.points, whole.colors, np.arange(len(whole)) % 10 == 0)
    write_outputs(folder, rows, whole.select(order), clouds, report, leaves, labels=labels)
    if grid:
        table = list(csv.DictReader(io.StringIO((folder / "plants.csv").read_text())))
        with (folder / "plants.csv").open("w", newline="") as handle:
            writer = csv.DictWriter(handle, [*table[0], "row", "column"], lineterminator="\n")
            writer.writeheader()
            for row in table:
                writer.writerow(row | {"row": 1, "column": row["plant"]})
    return folder


@pytest.fixture
def exported(tmp_path) -> Path:
    first = results_folder(tmp_path / "r1", 0, grid=True)
    second = results_folder(tmp_path / "r2", 1, grid=True, scale=1.5)
    out = tmp_path / "export"
    args = ["export", str(first), str(second), "--date", "2026-06-01", "--date", "2026-06-08"]
    assert main([*args, "--study", "plot-a", "--out", str(out)]) == 0
    return out


def test_plant_ids_of_every_point(tmp_path):
    cloud = labelled_cloud(results_folder(tmp_path / "r", 2))
    assert np.bincount(cloud.plant_id).tolist() == [300, 400, 400, 400]
    for plant, (x, y, _, _) in PLANTS.items():
        centre = cloud.points[cloud.plant_id == plant].mean(axis=0)
        assert np.hypot(centre[0] - x, centre[1] - y) < 0.01
    assert not cloud.organ.any()  # a cloud without labels: organs not measured
    assert not cloud.leaf_id.any() and not cloud.mixed.any()


def test_organs_leaves_and_mixed_pixels_of_every_point(tmp_path):
    """A run that measured organs writes each point's labels into cloud.ply; the export
    carries them (it once wrote organ 0 for every point, the organs measured or not)."""
    results = results_folder(tmp_path / "r", 2, organs=True)
    cloud = labelled_cloud(results)
    assert np.bincount(cloud.plant_id).tolist() == [300, 400, 400, 400]
    assert np.bincount(cloud.organ).tolist() == [300, 300, 900]
    assert np.bincount(cloud.leaf_id).tolist() == [600, 450, 450]
    assert cloud.mixed.sum() == 150
    for plant, (x, y, _, _) in PLANTS.items():
        centre = cloud.points[cloud.plant_id == plant].mean(axis=0)
        assert np.hypot(centre[0] - x, centre[1] - y) < 0.01
    out = tmp_path / "export"
    assert main(["export", str(results), "--formats", "laz,ply", "--out", str(out)]) == 0
    import laspy

    las = laspy.read(out / "cloud.laz")
    assert {"plant_id", "organ", "leaf_id", "mixed"} <= set(las.point_format.extra_dimension_names)
    from scipy.spatial import cKDTree

    distance, source = cKDTree(cloud.points).query(np.column_stack([las.x, las.y, las.z]))
    assert distance.max() < 1e-4 and len(np.unique(source)) == len(cloud.points)
    for name in ("plant_id", "organ", "leaf_id", "mixed"):
        np.testing.assert_array_equal(las[name], getattr(cloud, name)[source], err_msg=name)
    data = (out / "cloud.ply").read_bytes()
    header, _, body = data.partition(b"end_header\n")
    assert b"property uchar scalar_leaf_id" in header
    assert b"property uchar scalar_mixed" in header
    assert b"organ 0 none 1 stem 2 leaf 3 whorl" in header
    vertices = np.frombuffer(body, EXPORTED_VERTEX)
    assert np.bincount(vertices["organ"]).tolist() == [300, 300, 900]
    assert vertices["mixed"].sum() == 150


def test_laz_1_4_with_plant_id_and_organ_dimensions(exported):
    import laspy

    raw = (exported / "cloud.laz").read_bytes()
    assert raw[104] & 0x80, "LAZ: the point format's compression bit is set"
    las = laspy.read(exported / "cloud.laz")
    assert str(las.header.version) == "1.4"
    assert las.header.point_format.id == 7
    assert {"plant_id", "organ"} <= set(las.point_format.extra_dimension_names)
    assert np.bincount(np.asarray(las.plant_id)).tolist() == [300, 400, 400, 400]
    assert not np.asarray(las.organ).any()
    classes = np.asarray(las.classification)
    assert set(classes[np.asarray(las.plant_id) > 0]) == {3}
    reference = labelled_cloud(exported.parent / "r2")  # the latest date's cloud
    points = np.column_stack([las.x, las.y, las.z])
    np.testing.assert_allclose(
        np.sort(points, axis=0), np.sort(reference.points, axis=0), atol=6e-5
    )


def test_ply_with_scalar_fields_reads_back(exported):
    data = (exported / "cloud.ply").read_bytes()
    header, _, body = data.partition(b"end_header\n")
    assert b"property uint scalar_plant_id" in header  # CloudCompare: scalar field plant_id
    assert b"property uchar scalar_organ" in header
    vertices = np.frombuffer(body, EXPORTED_VERTEX)
    assert np.bincount(vertices["plant_id"]).tolist() == [300, 400, 400, 400]
    import open3d as o3d

    assert len(o3d.io.read_point_cloud(str(exported / "cloud.ply")).points) == 1500


def test_csvs_carry_units_in_their_headers(exported):
    wide = list(csv.DictReader(io.StringIO((exported / "plants.csv").read_text())))
    assert list(wide[0]) == [
        "plant_id", "date", "x_m", "y_m", "row", "column", "height_cm", "width_cm"
    ]  # fmt: skip
    assert len(wide) == 6
    assert {(r["date"], r["plant_id"], r["height_cm"]) for r in wide} >= {
        ("2026-06-01", "3", "25.75"),
        ("2026-06-08", "3", "38.62"),  # plants.csv of the results: 2 decimals
    }
    long = list(csv.DictReader(io.StringIO((exported / "observations.csv").read_text())))
    assert len(long) == 3 * 2 * 2  # plants x variables x dates
    assert {(r["variable"], r["unit"]) for r in long} == {
        ("plant_height_cm", "cm"),
        ("plant_width_cm", "cm"),
    }
    assert all(r["method"] for r in long)


def test_brapi_units_observations_and_variables(exported):
    units = json.loads((exported / "brapi" / "observationunits.json").read_text())
    observations = json.loads((exported / "brapi" / "observations.json").read_text())
    variables = json.loads((exported / "brapi" / "observationvariables.json").read_text())
    for document in (units, observations, variables):
        pagination = document["metadata"]["pagination"]
        assert pagination["totalCount"] == len(document["result"]["data"])
    data = units["result"]["data"]
    assert [u["observationUnitName"] for u in data] == ["plant 1", "plant 2", "plant 3"]
    position = data[2]["observationUnitPosition"]
    assert position["observationLevel"] == {"levelName": "plant", "levelOrder": 0, "levelCode": "3"}
    assert (position["positionCoordinateX"], position["positionCoordinateXType"]) == (
        "3",
        "GRID_COL",
    )
    assert (position["positionCoordinateY"], position["positionCoordinateYType"]) == (
        "1",
        "GRID_ROW",
    )
    assert data[2]["additionalInfo"]["x_m"] == 2.0
    rows = observations["result"]["data"]
    assert len(rows) == 12 and len({r["observationDbId"] for r in rows}) == 12
    unit_ids = {u["observationUnitDbId"] for u in data}
    variable_ids = {v["observationVariableDbId"] for v in variables["result"]["data"]}
    assert {r["observationUnitDbId"] for r in rows} == unit_ids
    assert {r["observationVariableDbId"] for r in rows} == variable_ids
    height = [
        r
        for r in rows
        if r["observationUnitName"] == "plant 1" and "height" in r["observationVariableName"]
    ]
    assert [(r["observationTimeStamp"][:10], r["value"]) for r in height] == [
        ("2026-06-01", "21.5"),
        ("2026-06-08", "32.25"),
    ]
    scales = {
        v["observationVariableName"]: v["scale"]["units"] for v in variables["result"]["data"]
    }
    assert scales == {"plant_height_cm": "cm", "plant_width_cm": "cm"}


def _table(path: Path) -> list[list[str]]:
    rows = list(csv.reader(io.StringIO(path.read_text()), delimiter="\t"))
    assert len({len(r) for r in rows}) == 1, f"{path.name}: rows of different lengths"
    return rows


def _investigation(path: Path) -> dict[str, list[str]]:
    fields = {}
    for line in path.read_text().splitlines():
        cells = line.split("\t")
        if len(cells) > 1 or not cells[0].isupper():
            fields[cells[0]] = cells[1:]
    return fields


def test_isa_tab_bundle_is_complete_and_consistent(exported):
    folder = exported / "isa"
    text = (folder / "i_investigation.txt").read_text()
    sections = [line for line in text.splitlines() if line.isupper() and "\t" not in line]
    assert sections == [
        "ONTOLOGY SOURCE REFERENCE", "INVESTIGATION", "INVESTIGATION PUBLICATIONS",
        "INVESTIGATION CONTACTS", "STUDY", "STUDY DESIGN DESCRIPTORS", "STUDY PUBLICATIONS",
        "STUDY FACTORS", "STUDY ASSAYS", "STUDY PROTOCOLS", "STUDY CONTACTS",
    ]  # fmt: skip
    fields = _investigation(folder / "i_investigation.txt")
    assert fields["Comment[MIAPPE Version]"] == ["1.1"]
    assert fields["Study Identifier"] == ["plot-a"]
    assert fields["Comment[Study Start Date]"] == ["2026-06-01"]
    study = _table(folder / fields["Study File Name"][0])
    assay = _table(folder / fields["Study Assay File Name"][0])
    definitions = _table(folder / fields["Comment[Trait Definition File]"][0])
    samples = {row[study[0].index("Sample Name")] for row in study[1:]}
    assert samples == {"plant 1", "plant 2", "plant 3"}
    protocols = set(fields["Study Protocol Name"])
    assert {row[study[0].index("Protocol REF")] for row in study[1:]} <= protocols
    assert {row[assay[0].index("Protocol REF")] for row in assay[1:]} <= protocols
    assert {row[0] for row in assay[1:]} == samples
    data_files = {row[assay[0].index("Derived Data File")] for row in assay[1:]}
    assert len(data_files) == 1
    traits = _table(folder / data_files.pop())
    assert {row[0] for row in traits[1:]} == {
        row[assay[0].index("Assay Name")] for row in assay[1:]
    }
    names = [row[definitions[0].index("Variable Name")] for row in definitions[1:]]
    assert traits[0][3:] == names
    units = {row[1]: row[definitions[0].index("Scale")] for row in definitions[1:]}
    assert units == {"plant_height_cm": "cm", "plant_width_cm": "cm"}
    assert all(row[definitions[0].index("Method Description")] for row in definitions[1:])


def test_formats_and_dates_are_chosen(tmp_path, capsys):
    folder = results_folder(tmp_path / "r", 3)
    out = tmp_path / "out"
    assert main(["export", str(folder), "--formats", "csv", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["observations.csv", "plants.csv"]
    assert "the day the results were written; give --date" in capsys.readouterr().out
    wide = list(csv.DictReader(io.StringIO((out / "plants.csv").read_text())))
    assert wide[0]["row"] == "" and wide[0]["column"] == ""
    assert main(["export", str(folder), "--formats", "las", "--out", str(out)]) == 1
    assert "choose among csv, laz, ply, isa, brapi" in capsys.readouterr().err


def test_every_leaf_of_every_date(tmp_path):
    """Each date's leaves.csv becomes one table, the date after the plant; a date without
    organs measured adds no leaf."""
    first = results_folder(tmp_path / "r1", 0, organs=True)
    second = results_folder(tmp_path / "r2", 1, scale=1.5, organs=True)
    third = results_folder(tmp_path / "r3", 2)  # organs not measured
    out = tmp_path / "export"
    args = ["export", str(first), str(second), str(third), "--formats", "csv", "--out", str(out)]
    dates = ["--date", "2026-06-01", "--date", "2026-06-08", "--date", "2026-06-15"]
    assert main([*args, *dates]) == 0
    rows = list(csv.DictReader(io.StringIO((out / "leaves.csv").read_text())))
    assert list(rows[0]) == [
        "plant_id", "date", "leaf_id", "length_cm", "max_width_cm", "area_cm2",
        "angle_from_stem_deg", "azimuth_deg", "insertion_height_cm",
    ]  # fmt: skip
    assert len(rows) == 2 * 3 * 2  # dates x plants x leaves
    assert {r["date"] for r in rows} == {"2026-06-01", "2026-06-08"}
    second_leaf = [r for r in rows if r["date"] == "2026-06-08" and r["plant_id"] == "3"][1]
    assert second_leaf["leaf_id"] == "2" and second_leaf["length_cm"] == "47"
    assert second_leaf["area_cm2"] == "123" and second_leaf["azimuth_deg"] == "180"


def test_a_broken_leaves_csv_is_named_with_its_field(tmp_path):
    import datetime as dt

    from fieldapp.export.data import from_results_dirs

    folder = results_folder(tmp_path / "r", 4, organs=True)
    text = (folder / "leaves.csv").read_text().splitlines()
    text[3] = text[3].replace("5.50", "wide")
    (folder / "leaves.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(FieldappError, match=r"leaves\.csv.*4.*max_width_cm.*wide"):
        from_results_dirs([folder], [dt.date(2026, 6, 1)], "plot")


def test_a_broken_plants_csv_is_named_with_its_field(tmp_path):
    import datetime as dt

    from fieldapp.export.data import from_results_dirs

    folder = results_folder(tmp_path / "r", 4)
    text = (folder / "plants.csv").read_text().replace("21.50", "tall")
    (folder / "plants.csv").write_text(text)
    with pytest.raises(FieldappError, match=r"plants\.csv: line 2, height_cm: 'tall'"):
        from_results_dirs([folder], [dt.date(2026, 6, 1)], "plot")


def test_the_results_database_gives_dates_and_season_ids(tmp_path, capsys):
    db = tmp_path / "season.sqlite"
    first = results_folder(tmp_path / "r1", 5)
    second = results_folder(tmp_path / "r2", 6, scale=1.25)
    for folder, date in ((first, "2026-06-01"), (second, "2026-06-08")):
        args = ["results", "--db", str(db), "add", str(folder), "--plot", "plot-b"]
        assert main([*args, "--date", date]) == 0
    out = tmp_path / "season"
    assert main(["export", "--plot", "plot-b", "--db", str(db), "--out", str(out)]) == 0
    long = list(csv.DictReader(io.StringIO((out / "observations.csv").read_text())))
    assert {r["date"] for r in long} == {"2026-06-01", "2026-06-08"}
    assert {r["plant_id"] for r in long} == {"1", "2", "3"}
    assert (out / "cloud.laz").is_file()
    single = tmp_path / "single"
    assert (
        main(["export", str(second), "--db", str(db), "--formats", "csv", "--out", str(single)])
        == 0
    )
    assert "the day the results were written" not in capsys.readouterr().out
    wide = list(csv.DictReader(io.StringIO((single / "plants.csv").read_text())))
    assert {r["date"] for r in wide} == {"2026-06-08"}


def test_variables_are_told_from_positions_and_ids():
    from fieldapp.export.variables import variable_of

    assert variable_of("height_cm").unit == "cm"
    assert variable_of("leaf_area_cm2").trait == "leaf area"
    assert variable_of("internode_length_mm").unit == "mm"
    for column in ("plant", "x_m", "map_x_m", "field_y_m", "grid_row", "points", "row"):
        assert variable_of(column) is None, column


def test_organ_traits_are_exported_and_blank_cells_are_no_observation(tmp_path):
    """plants.csv's organ columns are variables; a blank cell (not measured on that plant) gives
    no observation and an empty cell, never "nan"; a column blank everywhere is no variable."""
    folder = results_folder(tmp_path / "r", 0)
    table = list(csv.DictReader(io.StringIO((folder / "plants.csv").read_text())))
    table[0]["leaf_count"], table[1]["leaf_count"] = "6", "7"  # plant 3: not measured
    with (folder / "plants.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, list(table[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(table)
    out = tmp_path / "export"
    assert main(["export", str(folder), "--date", "2026-06-01", "--out", str(out)]) == 0
    long = list(csv.DictReader(io.StringIO((out / "observations.csv").read_text())))
    counts = {(r["plant_id"], r["value"]) for r in long if r["variable"].startswith("leaf_count")}
    assert counts == {("1", "6"), ("2", "7")}
    assert {r["variable"] for r in long} == {"plant_height_cm", "plant_width_cm", "leaf_count"}
    observations = (out / "brapi" / "observations.json").read_text()
    assert "nan" not in observations.lower()
