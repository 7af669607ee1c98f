"""The project's one PLY reader and writer.

Writes binary little-endian PLY with any per-point fields (a numpy structured array, one field
a vertex property). Reads binary (both byte orders) and ASCII PLY with any scalar vertex
properties into a structured array whose dtype comes from the header; other elements (faces,
edges) are skipped where their size allows it. Bad files raise :class:`PlyError` naming the file.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fieldapp.errors import FieldappError
from fieldapp.io.durable import write_bytes_durably

TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
"""PLY scalar types and their numpy kinds (byte order added from the format line)."""
NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint"}
NAMES |= {"f4": "float", "f8": "double"}
ORDERS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "<"}
COLOR_NAMES = (("red", "green", "blue"), ("diffuse_red", "diffuse_green", "diffuse_blue"))


class PlyError(FieldappError, ValueError):
    """A PLY file that cannot be read; the message names the file and what is wrong."""


@dataclass
class _Element:
    name: str
    count: int
    properties: list[tuple[str, str]] = field(default_factory=list)
    has_list: bool = False


def ply_bytes(vertices: NDArray[np.void], comments: Sequence[str] = ()) -> bytes:
    """A binary little-endian PLY of ``vertices`` (N,) structured: one property per field, in
    its order and under its name; fields must be scalar integers or floats."""
    names = vertices.dtype.names or ()
    if not names:
        raise ValueError("PLY vertices need named fields")
    lines = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments)]
    lines.append(f"element vertex {len(vertices)}")
    layout = []
    for name in names:
        kind = vertices.dtype.fields[name][0]  # type: ignore[index]
        key = f"{kind.kind}{kind.itemsize}"
        if key not in NAMES or kind.shape:
            raise ValueError(f"PLY field {name!r}: type {kind} has no PLY scalar type")
        lines.append(f"property {NAMES[key]} {name}")
        layout.append((name, "<" + key))
    lines.append("end_header")
    little = np.empty(len(vertices), np.dtype(layout))
    for name in names:
        little[name] = vertices[name]
    return ("\n".join(lines) + "\n").encode("ascii") + little.tobytes()


def write_ply(path: Path, vertices: NDArray[np.void], comments: Sequence[str] = ()) -> None:
    """Write :func:`ply_bytes` of ``vertices`` to ``path`` durably."""
    write_bytes_durably(path, ply_bytes(vertices, comments))


def read_ply(path: Path) -> NDArray[np.void]:
    """The vertices of the PLY file ``path``: (N,) structured, one field per vertex property,
    in the file's byte order. Raises :class:`PlyError` naming the file when it is missing, not a
    PLY file, truncated, or has vertex properties this reader cannot lay out (lists); a missing
    file raises FileNotFoundError (which names it), as callers tell it apart."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise
    except OSError as error:
        raise PlyError(f"{path}: cannot read ({error.strerror})") from None
    return parse_ply(data, str(path))


def parse_ply(data: bytes, name: str = "PLY data") -> NDArray[np.void]:
    """:func:`read_ply` of bytes already read; ``name`` names them in errors."""
    if not data.startswith((b"ply\n", b"ply\r\n")):
        raise PlyError(f"{name}: not a PLY file (it does not start with 'ply')")
    end = data.find(b"end_header")
    if end < 0:
        raise PlyError(f"{name}: PLY header has no end_header")
    body = data.index(b"\n", end) + 1 if b"\n" in data[end:] else len(data)
    fmt, elements = _header(data[:end].decode("ascii", "replace"), name)
    if fmt == "ascii":
        return _ascii(data[body:], elements, name)
    return _binary(data[body:], elements, ORDERS[fmt], name)


def _header(text: str, name: str) -> tuple[str, list[_Element]]:
    fmt = ""
    elements: list[_Element] = []
    for number, line in enumerate(text.splitlines()[1:], start=2):
        parts = line.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format" and len(parts) == 3 and parts[1] in ORDERS:
            fmt = parts[1]
        elif parts[0] == "element" and len(parts) == 3 and parts[2].isdigit():
            elements.append(_Element(parts[1], int(parts[2])))
        elif parts[0] == "property" and elements and parts[1:2] == ["list"] and len(parts) == 5:
            elements[-1].has_list = True
        elif parts[0] == "property" and elements and len(parts) == 3 and parts[1] in TYPES:
            elements[-1].properties.append((parts[2], TYPES[parts[1]]))
        else:
            raise PlyError(f"{name}: PLY header line {number} not understood: {line.strip()!r}")
    if not fmt:
        raise PlyError(f"{name}: PLY header has no format line (ascii or binary)")
    if not any(e.name == "vertex" for e in elements):
        raise PlyError(f"{name}: PLY file has no vertex element")
    return fmt, elements


def _vertex_dtype(element: _Element, order: str, name: str) -> np.dtype[np.void]:
    if element.has_list:
        raise PlyError(f"{name}: PLY vertex element has list properties; not supported")
    names = [p for p, _ in element.properties]
    if len(set(names)) != len(names):
        raise PlyError(f"{name}: PLY vertex properties repeat a name")
    return np.dtype([(p, order + kind) for p, kind in element.properties])


def _binary(body: bytes, elements: list[_Element], order: str, name: str) -> NDArray[np.void]:
    offset = 0
    for element in elements:
        if element.name == "vertex":
            dtype = _vertex_dtype(element, order, name)
            size = dtype.itemsize * element.count
            if len(body) - offset < size:
                raise PlyError(
                    f"{name}: PLY file is truncated: {element.count} vertices need {size} "
                    f"bytes, {max(0, len(body) - offset)} left"
                )
            return np.frombuffer(body, dtype, element.count, offset).copy()
        if element.has_list:
            raise PlyError(f"{name}: PLY element {element.name!r} with lists before the vertices")
        offset += np.dtype([(p, order + k) for p, k in element.properties]).itemsize * element.count
    raise AssertionError("unreachable: the header has a vertex element")


def _ascii(body: bytes, elements: list[_Element], name: str) -> NDArray[np.void]:
    lines = body.decode("ascii", "replace").splitlines()
    start = 0
    for element in elements:
        if element.name != "vertex":
            start += element.count
            continue
        dtype = _vertex_dtype(element, "<", name)
        rows = lines[start : start + element.count]
        if len(rows) < element.count:
            raise PlyError(
                f"{name}: PLY file is truncated: {element.count} vertices, {len(rows)} lines"
            )
        return _ascii_rows(rows, dtype, name)
    raise AssertionError("unreachable: the header has a vertex element")


def _ascii_rows(rows: list[str], dtype: np.dtype[np.void], name: str) -> NDArray[np.void]:
    """The vertex lines as one table (numpy's C parser); a bad line is found and named."""
    names = dtype.names or ()
    vertices = np.empty(len(rows), dtype)
    if not rows:
        return vertices
    try:
        table = np.loadtxt(rows, np.float64, comments=None, ndmin=2)
    except ValueError:
        table = np.empty((0, 0))
    if table.shape != (len(rows), len(names)):
        raise PlyError(f"{name}: {_bad_row(rows, len(names))}")
    for column, field_name in enumerate(names):
        vertices[field_name] = table[:, column]
    return vertices


def _bad_row(rows: list[str], width: int) -> str:
    """What is wrong with the first vertex line that is not ``width`` numbers."""
    for index, row in enumerate(rows):
        values = row.split()
        if len(values) != width:
            return f"PLY vertex {index}: {len(values)} values, {width} properties"
        try:
            [float(v) for v in values]
        except ValueError:
            return f"PLY vertex {index}: not numbers: {row!r}"
    return "PLY vertices are not a table of numbers"


def points_of(vertices: NDArray[np.void], name: str = "PLY data") -> NDArray[np.float64]:
    """(N, 3) float64 of the ``x``, ``y``, ``z`` properties; PlyError when one is missing."""
    missing = [a for a in "xyz" if a not in (vertices.dtype.names or ())]
    if missing:
        raise PlyError(f"{name}: PLY vertices have no {', '.join(missing)} property")
    return np.stack([vertices[a].astype(np.float64) for a in "xyz"], axis=1)


def colors_of(vertices: NDArray[np.void]) -> NDArray[np.uint8] | None:
    """(N, 3) uint8 of ``red``, ``green``, ``blue`` (or ``diffuse_*``), None when absent:
    8-bit kept, 16-bit scaled down, floats taken as 0-1."""
    fields = vertices.dtype.names or ()
    for names in COLOR_NAMES:
        if all(n in fields for n in names):
            rgb = np.stack([vertices[n] for n in names], axis=1)
            if rgb.dtype.kind == "f":
                scaled = np.rint(rgb.astype(np.float64) * 255.0)
                return np.clip(scaled, 0, 255).astype(np.uint8)
            if rgb.dtype.itemsize > 1:
                shifted: NDArray[np.int64] = rgb.astype(np.int64) >> 8
                return np.clip(shifted, 0, 255).astype(np.uint8)
            return np.asarray(rgb, np.uint8)
    return None
