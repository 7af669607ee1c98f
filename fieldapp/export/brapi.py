"""BrAPI v2 JSON: observation units (one per plant), observations (one per trait and date)
and the observation variables, each as a BrAPI list response (``metadata`` + ``result.data``).

A plant's grid position is ``positionCoordinateX/Y`` of type ``GRID_COL``/``GRID_ROW`` when the
results carry the planting grid's column and row; its position in the field frame (m) is in
``additionalInfo`` in every case.
"""

from __future__ import annotations

import math
from typing import Any

from fieldapp.export.data import ExportData, PlantObservation
from fieldapp.export.variables import Variable


def response(data: list[dict[str, Any]]) -> dict[str, Any]:
    """A BrAPI v2 list response holding ``data`` on one page."""
    return {
        "@context": ["https://brapi.org/jsonld/context/metadata.jsonld"],
        "metadata": {
            "datafiles": [],
            "pagination": {
                "currentPage": 0,
                "pageSize": len(data),
                "totalCount": len(data),
                "totalPages": 1,
            },
            "status": [{"message": "exported by fieldapp", "messageType": "INFO"}],
        },
        "result": {"data": data},
    }


def unit_id(study: str, plant_id: int) -> str:
    return f"{study}:plant:{plant_id}"


def observation_units(data: ExportData) -> dict[str, Any]:
    latest: dict[int, PlantObservation] = {}
    for o in sorted(data.observations, key=lambda o: o.date):
        latest[o.plant_id] = o
    return response([_unit(data.study, o) for _, o in sorted(latest.items())])


def _unit(study: str, o: PlantObservation) -> dict[str, Any]:
    position: dict[str, Any] = {
        "entryType": "TEST",
        "observationLevel": {"levelName": "plant", "levelOrder": 0, "levelCode": str(o.plant_id)},
    }
    if o.row is not None and o.column is not None:
        position |= {
            "positionCoordinateX": str(o.column),
            "positionCoordinateXType": "GRID_COL",
            "positionCoordinateY": str(o.row),
            "positionCoordinateYType": "GRID_ROW",
        }
    return {
        "observationUnitDbId": unit_id(study, o.plant_id),
        "observationUnitName": f"plant {o.plant_id}",
        "studyDbId": study,
        "studyName": study,
        "observationUnitPosition": position,
        "additionalInfo": {
            "x_m": round(o.x_m, 4),
            "y_m": round(o.y_m, 4),
            "frame": "fieldapp field frame (the mission's map frame when known), metres",
        },
    }


def observations(data: ExportData) -> dict[str, Any]:
    rows = []
    for o in sorted(data.observations, key=lambda o: (o.date, o.plant_id)):
        for v in data.variables:
            if math.isnan(o.values[v.column]):
                continue  # not measured on this plant: no observation
            unit = unit_id(data.study, o.plant_id)
            rows.append(
                {
                    "observationDbId": f"{unit}:{v.name}:{o.date.isoformat()}",
                    "observationUnitDbId": unit,
                    "observationUnitName": f"plant {o.plant_id}",
                    "observationVariableDbId": v.variable_id,
                    "observationVariableName": v.name,
                    "observationTimeStamp": f"{o.date.isoformat()}T00:00:00Z",
                    "studyDbId": data.study,
                    "value": f"{o.values[v.column]:g}",
                }
            )
    return response(rows)


def observation_variables(data: ExportData) -> dict[str, Any]:
    return response([_variable(v) for v in data.variables])


def _variable(v: Variable) -> dict[str, Any]:
    return {
        "observationVariableDbId": v.variable_id,
        "observationVariableName": v.name,
        "trait": {"traitDbId": f"{v.variable_id}:trait", "traitName": v.trait},
        "method": {
            "methodDbId": f"{v.variable_id}:method",
            "methodName": f"fieldapp {v.trait}",
            "description": v.method,
        },
        "scale": {
            "scaleDbId": f"{v.variable_id}:scale",
            "scaleName": v.unit,
            "dataType": "Numerical",
            "units": v.unit,
        },
    }
