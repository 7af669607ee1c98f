"""Loading a JSON document into a pydantic model, with every problem named by file and field."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ValidationError
from pydantic_core import PydanticCustomError

from devices.geometry import rigidity_problem
from fieldapp.errors import FormatError, Problem
from fieldapp.io.files import UnreadableFile, read_regular_file

ModelT = TypeVar("ModelT", bound=BaseModel)

MAX_JSON_BYTES = 64 * 1024 * 1024


def field_path(loc: tuple[int | str, ...]) -> str:
    """``("captures", 3, "depth")`` -> ``"captures[3].depth"``."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"{text} is out of the range of a number")
    return value


def read_json(path: Path) -> Any:
    """Parse ``path`` as strict JSON (no NaN/Infinity); raise :class:`FormatError` if it is not."""
    try:
        text = read_regular_file(path, MAX_JSON_BYTES, "a session file").decode("utf-8")
    except UnreadableFile as error:
        raise FormatError([Problem(str(path), "", str(error))]) from None
    except UnicodeDecodeError:
        raise FormatError([Problem(str(path), "", "not UTF-8 text")]) from None
    try:
        return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float)
    except json.JSONDecodeError as error:
        where = f"line {error.lineno} column {error.colno}"
        raise FormatError([Problem(str(path), where, f"malformed JSON: {error.msg}")]) from None
    except ValueError as error:
        raise FormatError([Problem(str(path), "", f"malformed JSON: {error}")]) from None
    except RecursionError:
        raise FormatError([Problem(str(path), "", "malformed JSON: nested too deeply")]) from None


def validate_document(path: Path, document: Any, model: type[ModelT]) -> ModelT:
    """Validate a parsed document; raise :class:`FormatError` with one problem per bad field."""
    try:
        return model.model_validate(document)
    except ValidationError as error:
        problems = [
            Problem(str(path), field_path(e["loc"]) or "(document)", e["msg"])
            for e in error.errors(include_url=False)
        ]
        raise FormatError(problems) from None


def load_model(path: Path, model: type[ModelT]) -> ModelT:
    """Read and validate ``path`` as ``model``."""
    return validate_document(path, read_json(path), model)


def to_rigid_matrix(value: Any) -> NDArray[np.float64]:
    """Pydantic validator: a finite 4 x 4 rigid transform from nested lists."""
    if isinstance(value, np.ndarray):
        matrix = value.astype(np.float64)
    else:
        if not (isinstance(value, list) and all(isinstance(row, list) for row in value)):
            raise PydanticCustomError("matrix", "must be a 4 x 4 matrix as nested lists")
        rows = [[_number(x) for x in row] for row in value]
        if len(rows) != 4 or any(len(row) != 4 for row in rows):
            raise PydanticCustomError("matrix", "must be a 4 x 4 matrix as nested lists")
        matrix = np.array(rows, dtype=np.float64)
    problem = rigidity_problem(matrix)
    if problem:
        raise PydanticCustomError("rigid", "matrix {problem}", {"problem": problem})
    return matrix


def _number(x: Any) -> float:
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise PydanticCustomError("matrix", "matrix entries must be numbers")
    if not math.isfinite(x):
        raise PydanticCustomError("rigid", "matrix has a NaN or infinite entry")
    return float(x)
