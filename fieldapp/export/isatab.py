"""A MIAPPE ISA-Tab bundle: ``i_investigation.txt``, ``s_study.txt``, ``a_phenotyping.txt``,
the trait data ``d_traits.txt`` and the trait definition file ``tdf.txt`` (variable, trait,
method, scale/unit per variable), following the MIAPPE v1.1 ISA-Tab mapping.
"""

from __future__ import annotations

import datetime as dt
import math

from fieldapp.export.data import ExportData, PlantObservation

INVESTIGATION = "i_investigation.txt"
STUDY = "s_study.txt"
ASSAY = "a_phenotyping.txt"
DATA = "d_traits.txt"
TRAITS = "tdf.txt"


def _row(*cells: object) -> str:
    return "\t".join(_cell(c) for c in cells) + "\n"


def _cell(value: object) -> str:
    text = "" if value is None else str(value)
    return f'"{text}"' if any(c in text for c in '\t\n"') else text


def _sample(plant_id: int) -> str:
    return f"plant {plant_id}"


def _assay(plant_id: int, date: dt.date) -> str:
    return f"plant {plant_id} {date.isoformat()}"


def investigation(data: ExportData, today: dt.date) -> str:
    """The investigation file: one study, one phenotyping assay, its protocol."""
    first, last = data.dates[0], data.dates[-1]
    sections = [
        "ONTOLOGY SOURCE REFERENCE\n",
        _row("Term Source Name"),
        _row("Term Source File"),
        _row("Term Source Version"),
        _row("Term Source Description"),
        "INVESTIGATION\n",
        _row("Investigation Identifier", data.study),
        _row("Investigation Title", f"{data.study}: maize seedling phenotyping"),
        _row("Investigation Description", "Kinect v2 turntable scans reconstructed by fieldapp"),
        _row("Investigation Submission Date", today.isoformat()),
        _row("Investigation Public Release Date", ""),
        _row("Comment[MIAPPE Version]", "1.1"),
        "INVESTIGATION PUBLICATIONS\n",
        _row("Investigation PubMed ID"),
        _row("Investigation Publication DOI"),
        _row("Investigation Publication Author List"),
        _row("Investigation Publication Title"),
        _row("Investigation Publication Status"),
        _row("Investigation Publication Status Term Accession Number"),
        _row("Investigation Publication Status Term Source REF"),
        "INVESTIGATION CONTACTS\n",
        *(_row(f"Investigation Person {n}") for n in _PERSON),
        "STUDY\n",
        _row("Study Identifier", data.study),
        _row("Study Title", f"{data.study}: plant height and width"),
        _row("Study Description", "per-plant traits from 3D reconstruction, by date"),
        _row("Comment[Study Start Date]", first.isoformat()),
        _row("Comment[Study End Date]", last.isoformat()),
        _row("Comment[Type of Growth Facility]", "field"),
        _row("Comment[Study Data File Link]", DATA),
        _row("Comment[Study Data File Description]", "per-plant traits by date"),
        _row("Comment[Trait Definition File]", TRAITS),
        _row("Comment[Observation Unit Level Hierarchy]", "plant"),
        _row("Comment[Observation Unit Description]", "one maize plant in the plot"),
        _row("Study Submission Date", today.isoformat()),
        _row("Study Public Release Date", ""),
        _row("Study File Name", STUDY),
        "STUDY DESIGN DESCRIPTORS\n",
        _row("Study Design Type", "observational"),
        _row("Study Design Type Term Accession Number", ""),
        _row("Study Design Type Term Source REF", ""),
        "STUDY PUBLICATIONS\n",
        _row("Study PubMed ID"),
        _row("Study Publication DOI"),
        _row("Study Publication Author List"),
        _row("Study Publication Title"),
        _row("Study Publication Status"),
        _row("Study Publication Status Term Accession Number"),
        _row("Study Publication Status Term Source REF"),
        "STUDY FACTORS\n",
        _row("Study Factor Name"),
        _row("Study Factor Type"),
        _row("Study Factor Type Term Accession Number"),
        _row("Study Factor Type Term Source REF"),
        "STUDY ASSAYS\n",
        _row("Study Assay File Name", ASSAY),
        _row("Study Assay Measurement Type", "phenotyping"),
        _row("Study Assay Measurement Type Term Accession Number", ""),
        _row("Study Assay Measurement Type Term Source REF", ""),
        _row("Study Assay Technology Type", "plant level analysis"),
        _row("Study Assay Technology Type Term Accession Number", ""),
        _row("Study Assay Technology Type Term Source REF", ""),
        _row(
            "Study Assay Technology Platform",
            "3D reconstruction from depth images (Kinect v2 on a rotary table; fieldapp)",
        ),
        "STUDY PROTOCOLS\n",
        _row("Study Protocol Name", *PROTOCOLS),
        _row("Study Protocol Type", *PROTOCOLS),
        *(_row(f"Study Protocol {n}", *("",) * len(PROTOCOLS)) for n in _PROTOCOL_EMPTY[:2]),
        _row("Study Protocol Description", *PROTOCOLS.values()),
        *(_row(f"Study Protocol {n}", *("",) * len(PROTOCOLS)) for n in _PROTOCOL_EMPTY[2:]),
        "STUDY CONTACTS\n",
        *(_row(f"Study Person {n}") for n in _PERSON),
    ]
    return "".join(sections)


_PERSON = (
    "Last Name",
    "First Name",
    "Mid Initials",
    "Email",
    "Phone",
    "Fax",
    "Address",
    "Affiliation",
    "Roles",
    "Roles Term Accession Number",
    "Roles Term Source REF",
)
_PROTOCOL_EMPTY = (
    "Type Term Accession Number",
    "Type Term Source REF",
    "URI",
    "Version",
    "Parameters Name",
    "Parameters Name Term Accession Number",
    "Parameters Name Term Source REF",
    "Components Name",
    "Components Type",
    "Components Type Term Accession Number",
    "Components Type Term Source REF",
)
_PHENOTYPING = (
    "depth images of each station turned through its views, joined by the calibrated view "
    "step and station transforms, levelled on the ground, plant points by excess green and "
    "height, refined by ICP, plants by clustering; traits measured on each plant's cloud"
)


PROTOCOLS = {
    "Growth": "maize seedlings growing in a field plot",
    "Phenotyping": _PHENOTYPING,
    "Data Transformation": "per-plant traits computed from each plant's point cloud",
}
"""Protocol name (and type, as the MIAPPE configuration names them) -> description."""


def _position(o: PlantObservation) -> str:
    """MIAPPE spatial distribution, ``type:value`` pairs: grid cell when known, else x and y
    in the field frame (m)."""
    if o.row is not None and o.column is not None:
        return f"row:{o.row};column:{o.column}"
    return f"x:{o.x_m:.3f};y:{o.y_m:.3f}"


def study(data: ExportData) -> str:
    """One source (the plot's maize), one sample (observation unit) per plant."""
    lines = [
        _row(
            "Source Name",
            "Characteristics[Organism]",
            "Protocol REF",
            "Sample Name",
            "Characteristics[Observation Unit Type]",
            "Characteristics[Spatial Distribution]",
        )
    ]
    latest = {o.plant_id: o for o in sorted(data.observations, key=lambda o: o.date)}
    for plant_id, o in sorted(latest.items()):
        lines.append(
            _row(data.study, "Zea mays", "Growth", _sample(plant_id), "plant", _position(o))
        )
    return "".join(lines)


def assay(data: ExportData) -> str:
    """One assay per plant and date: the plant's cloud of that date (raw), the trait data
    file (derived)."""
    lines = [
        _row(
            "Sample Name",
            "Characteristics[Observation Unit Type]",
            "Protocol REF",
            "Assay Name",
            "Raw Data File",
            "Protocol REF",
            "Derived Data File",
        )
    ]
    for o in sorted(data.observations, key=lambda o: (o.plant_id, o.date)):
        raw = f"{o.date.isoformat()}/plants/{o.plant_id}.ply"
        lines.append(
            _row(
                _sample(o.plant_id),
                "plant",
                "Phenotyping",
                _assay(o.plant_id, o.date),
                raw,
                "Data Transformation",
                DATA,
            )
        )
    return "".join(lines)


def _value(value: float) -> str:
    """A trait's cell: blank where it was not measured."""
    return "" if math.isnan(value) else f"{value:g}"


def trait_data(data: ExportData) -> str:
    """One row per assay (plant and date), one column per variable (its name)."""
    lines = [_row("Assay Name", "Sample Name", "Date", *(v.name for v in data.variables))]
    for o in sorted(data.observations, key=lambda o: (o.plant_id, o.date)):
        values = (_value(o.values[v.column]) for v in data.variables)
        lines.append(
            _row(_assay(o.plant_id, o.date), _sample(o.plant_id), o.date.isoformat(), *values)
        )
    return "".join(lines)


def trait_definitions(data: ExportData) -> str:
    """Variable, trait, method (with its description) and scale (unit) of each variable."""
    lines = [_row("Variable ID", "Variable Name", "Trait", "Method", "Method Description", "Scale")]
    for v in data.variables:
        lines.append(_row(v.variable_id, v.name, v.trait, f"fieldapp {v.trait}", v.method, v.unit))
    return "".join(lines)


def bundle(data: ExportData, today: dt.date) -> dict[str, str]:
    """File name -> text of every file of the bundle."""
    return {
        INVESTIGATION: investigation(data, today),
        STUDY: study(data),
        ASSAY: assay(data),
        DATA: trait_data(data),
        TRAITS: trait_definitions(data),
    }
