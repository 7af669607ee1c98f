"""fieldapp.io.ply: the project's one PLY reader and writer."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fieldapp.io.ply import PlyError, colors_of, ply_bytes, points_of, read_ply, write_ply

VERTEX = np.dtype(
    [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("plant_id", "<i4"),
        ("leaf_id", "u1"),
        ("curvature", "<f8"),
        ("return_index", "<u2"),
        ("label", "i1"),
        ("segment", "<u4"),
        ("weight", "<i2"),
    ]
)


def _vertices(count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    vertices = np.empty(count, VERTEX)
    for name in VERTEX.names or ():
        kind = VERTEX[name]
        if kind.kind == "f":
            vertices[name] = rng.normal(0.0, 3.0, count)
        else:
            info = np.iinfo(kind)
            vertices[name] = rng.integers(info.min, info.max, count, endpoint=True)
    return vertices


def _header(fmt: str, count: int, properties: list[str], extra: str = "") -> bytes:
    lines = ["ply", f"format {fmt} 1.0", "comment from another tool", f"element vertex {count}"]
    lines += [f"property {p}" for p in properties] + [extra, "end_header", ""]
    return "\n".join(line for line in lines if line != "" or line is lines[-1]).encode("ascii")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_round_trip_keeps_every_field(tmp_path: Path, seed: int) -> None:
    vertices = _vertices(257, seed)
    path = tmp_path / "cloud.ply"
    write_ply(path, vertices, ["field frame, m"])
    back = read_ply(path)
    assert back.dtype.names == VERTEX.names
    for name in VERTEX.names or ():
        np.testing.assert_array_equal(back[name], vertices[name])
    assert path.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\ncomment field")


def test_native_and_big_endian_input_is_written_little_endian() -> None:
    vertices = np.zeros(3, [("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("i", ">u4")])
    vertices["x"], vertices["i"] = [1.5, -2.0, 3.25], [1, 2, 70000]
    data = ply_bytes(vertices)
    assert b"property double x\n" in data and b"property uint i\n" in data
    assert data.endswith(np.array([70000], "<u4").tobytes())


def test_empty_cloud_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "empty.ply"
    write_ply(path, np.empty(0, VERTEX))
    assert len(read_ply(path)) == 0 and read_ply(path).dtype.names == VERTEX.names


def test_big_endian_binary(tmp_path: Path) -> None:
    vertices = np.array([(1.0, 2.0, 3.0, 7), (-4.0, 5.5, 6.0, 300)], ">f4, >f4, >f4, >u2")
    vertices.dtype.names = ("x", "y", "z", "intensity")
    path = tmp_path / "big.ply"
    header = _header("binary_big_endian", 2, ["float x", "float y", "float z", "ushort intensity"])
    path.write_bytes(header + vertices.tobytes())
    back = read_ply(path)
    np.testing.assert_array_equal(points_of(back), [[1, 2, 3], [-4, 5.5, 6]])
    np.testing.assert_array_equal(back["intensity"], [7, 300])
    assert colors_of(back) is None


def test_ascii_with_faces_after_and_a_comment_element_before(tmp_path: Path) -> None:
    text = (
        "ply\nformat ascii 1.0\ncomment made by hand\nobj_info scanner 1\n"
        "element camera 1\nproperty float view_px\n"
        "element vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty int label\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "2.5\n"
        "0 0 0 255 0 0 -1\n1.25 0 -3 0 255 0 7\n0 1e-3 2 0 0 255 12\n3 0 1 2\n"
    )
    path = tmp_path / "hand.ply"
    path.write_text(text)
    back = read_ply(path)
    np.testing.assert_array_equal(points_of(back), [[0, 0, 0], [1.25, 0, -3], [0, 1e-3, 2]])
    np.testing.assert_array_equal(colors_of(back), [[255, 0, 0], [0, 255, 0], [0, 0, 255]])
    np.testing.assert_array_equal(back["label"], [-1, 7, 12])


def test_binary_faces_after_the_vertices_are_skipped(tmp_path: Path) -> None:
    vertices = _vertices(4, 3)[["x", "y", "z"]]
    data = ply_bytes(
        np.ascontiguousarray(vertices)
        .astype("<f4, <f4, <f4")
        .view(np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")]))
    )
    head, body = data.split(b"end_header\n")
    head += b"element face 1\nproperty list uchar int vertex_indices\n"
    path = tmp_path / "mesh.ply"
    path.write_bytes(
        head + b"end_header\n" + body + bytes([3]) + np.arange(3, dtype="<i4").tobytes()
    )
    np.testing.assert_array_equal(points_of(read_ply(path)), points_of(vertices))


def test_colours_of_other_tools() -> None:
    floats = np.array([(0.0, 0.5, 1.0)], [("red", "<f4"), ("green", "<f4"), ("blue", "<f4")])
    np.testing.assert_array_equal(colors_of(floats), [[0, 128, 255]])
    wide = np.array(
        [(65535, 256, 0)],
        [("diffuse_red", "<u2"), ("diffuse_green", "<u2"), ("diffuse_blue", "<u2")],
    )
    np.testing.assert_array_equal(colors_of(wide), [[255, 1, 0]])


def test_matches_open3d(tmp_path: Path) -> None:
    """A file Open3D writes (binary and ASCII) reads as Open3D reads it back."""
    o3d = pytest.importorskip("open3d")
    rng = np.random.default_rng(5)
    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(rng.normal(size=(50, 3)))
    cloud.colors = o3d.utility.Vector3dVector(rng.integers(0, 256, (50, 3)) / 255.0)
    for ascii in (False, True):
        path = tmp_path / f"open3d-{ascii}.ply"
        assert o3d.io.write_point_cloud(str(path), cloud, write_ascii=ascii)
        vertices = read_ply(path)
        theirs = o3d.io.read_point_cloud(str(path))
        np.testing.assert_array_equal(points_of(vertices), np.asarray(theirs.points))
        expected = np.rint(np.asarray(theirs.colors) * 255).astype(np.uint8)
        np.testing.assert_array_equal(colors_of(vertices), expected)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"", "not a PLY file"),
        (b"\x89PNG\r\n\x1a\n....", "not a PLY file"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no end_header"),
        (b"ply\nelement vertex 1\nproperty float x\nend_header\n1\n", "no format line"),
        (b"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no vertex element"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n1\n",
            "header line 4 not understood",
        ),
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
            b"end_header\n\x00\x00\x80?\x00",
            "truncated: 2 vertices need 8 bytes, 5 left",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n",
            "truncated: 3 vertices, 2 lines",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            b"end_header\n1\n",
            "vertex 0: 1 values, 2 properties",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\nabc\n",
            "vertex 0: not numbers",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int x\nend_header\n",
            "list properties",
        ),
    ],
)
def test_bad_files_are_named(tmp_path: Path, data: bytes, message: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(data)
    with pytest.raises(PlyError, match=rf"^{re.escape(str(path))}: .*{message}"):
        read_ply(path)


def test_missing_file_and_missing_coordinates_are_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"nothing\.ply"):
        read_ply(tmp_path / "nothing.ply")
    (tmp_path / "folder.ply").mkdir()
    with pytest.raises(PlyError, match=r"folder\.ply: cannot read"):
        read_ply(tmp_path / "folder.ply")
    with pytest.raises(PlyError, match=r"cloud\.ply: PLY vertices have no z property"):
        points_of(np.zeros(2, [("x", "<f4"), ("y", "<f4")]), "cloud.ply")
