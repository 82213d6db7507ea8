"""curvature.io: round trips of every format, PLY/PCD variants and the real scans."""

from __future__ import annotations

import json
import os
import struct

import numpy as np
import pytest

import curvature
from curvature.cloud import PointCloud
from curvature.errors import FormatError
from curvature.io import (
    FORMATS_READ,
    FORMATS_WRITE,
    format_from_path,
    read,
    read_bytes,
    read_result,
    write,
    write_bytes,
    write_stream,
)
from curvature.io.lzf import LZFError, lzf_decompress
from curvature.result import CurvatureResult

# --- builders ------------------------------------------------------------------------------

PLY_STRUCT = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h",
              "int16": "h", "ushort": "H", "uint16": "H", "int": "i", "int32": "i",
              "uint": "I", "uint32": "I", "float": "f", "float32": "f", "double": "d",
              "float64": "d"}


def _text(ptype: str, value) -> str:
    return repr(float(value)) if PLY_STRUCT[ptype] in "fd" else str(int(value))


def build_ply(fmt: str, elements, comments=()) -> bytes:
    """A PLY file from ``[(name, props, rows)]``; props are ``("scalar", type, name)`` or
    ``("list", count_type, item_type, name)``, rows tuples with lists for list props."""
    head = ["ply", f"format {fmt} 1.0", *[f"comment {c}" for c in comments]]
    for name, props, rows in elements:
        head.append(f"element {name} {len(rows)}")
        for p in props:
            head.append(f"property list {p[1]} {p[2]} {p[3]}" if p[0] == "list"
                        else f"property {p[1]} {p[2]}")
    head.append("end_header")
    out = bytearray(("\n".join(head) + "\n").encode())
    order = ">" if fmt == "binary_big_endian" else "<"
    for _, props, rows in elements:
        for row in rows:
            if fmt == "ascii":
                toks = []
                for p, v in zip(props, row, strict=True):
                    if p[0] == "list":
                        toks += [str(len(v))] + [_text(p[2], x) for x in v]
                    else:
                        toks.append(_text(p[1], v))
                out += (" ".join(toks) + "\n").encode()
            else:
                for p, v in zip(props, row, strict=True):
                    if p[0] == "list":
                        out += struct.pack(order + PLY_STRUCT[p[1]], len(v))
                        out += struct.pack(order + PLY_STRUCT[p[2]] * len(v), *v)
                    else:
                        out += struct.pack(order + PLY_STRUCT[p[1]], v)
    return bytes(out)


def grid_mesh(nx=5, ny=4):
    """(nx*ny, 3) vertices and quads [a, b, c, d] of a small curved grid."""
    xs, ys = np.meshgrid(np.linspace(0.0, 1.0, nx), np.linspace(0.0, 2.0, ny))
    pts = np.stack([xs.ravel(), ys.ravel(), 0.3 * (xs * ys).ravel() + 0.1], axis=1)
    quads = [[j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i]
             for j in range(ny - 1) for i in range(nx - 1)]
    return pts, quads


def fan(polys):
    return np.array([[p[0], p[k], p[k + 1]] for p in polys for k in range(1, len(p) - 1)])


def lzf_compress(data: bytes) -> bytes:
    """Small greedy LZF encoder (literals, short and long back references, overlaps)."""
    out, lit, table = bytearray(), bytearray(), {}
    n, i = len(data), 0

    def flush():
        while lit:
            chunk = lit[:32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
            del lit[:32]

    while i < n:
        key = data[i:i + 3]
        ref = table.get(key) if len(key) == 3 else None
        if len(key) == 3:
            table[key] = i
        if ref is not None and i - ref <= 8192:
            length, limit = 0, min(264, n - i)
            while length < limit and data[ref + length] == data[i + length]:
                length += 1
            if length >= 3:
                flush()
                dist, code = i - ref - 1, length - 2
                if code < 7:
                    out.append((code << 5) | (dist >> 8))
                else:
                    out += bytes([(7 << 5) | (dist >> 8), code - 7])
                out.append(dist & 0xFF)
                i += length
                continue
        lit.append(data[i])
        i += 1
    flush()
    return bytes(out)


def make_result(n=30, faces=True) -> CurvatureResult:
    rng = np.random.default_rng(7)
    pts = rng.normal(size=(n, 3))
    k1 = rng.normal(size=n)
    k2 = k1 - np.abs(rng.normal(size=n))
    status = np.zeros(n, dtype=np.int8)
    status[[2, 7, 11]] = [1, 2, 4]
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    dir1 = np.cross(normals, [0.0, 0.0, 1.0])
    dir1 /= np.linalg.norm(dir1, axis=1, keepdims=True)
    dir2 = np.cross(normals, dir1)
    bad = status != 0
    k1[bad] = k2[bad] = np.nan
    dir1[bad] = dir2[bad] = np.nan
    normals[2] = np.nan
    return CurvatureResult(
        points=pts, k1=k1, k2=k2, mean=(k1 + k2) / 2, gaussian=k1 * k2, normals=normals,
        dir1=dir1, dir2=dir2, neighbor_count=rng.integers(3, 40, n).astype(np.int32),
        status=status, residual=np.abs(rng.normal(size=n)) * 1e-3,
        k1_std=np.where(bad, np.nan, rng.uniform(0.01, 0.1, n)),
        k2_std=np.where(bad, np.nan, rng.uniform(0.01, 0.1, n)),
        mean_std=np.where(bad, np.nan, rng.uniform(0.01, 0.1, n)),
        uncertain=(bad | (rng.uniform(size=n) < 0.3)).astype(np.uint8),
        faces=rng.integers(0, n, size=(12, 3)) if faces else None,
        info={"method": "knn", "fit": "implicit", "params": {"k": 24}, "seconds": 0.25})


def test_result_without_standard_errors_reads_back_with_nan(tmp_path):
    """A result file written before the standard errors existed still reads as a result."""
    res = make_result()
    path = tmp_path / "res.csv"
    write(path, res)
    rows = [line.split(",") for line in path.read_text().splitlines()]
    drop = {rows[0].index(name) for name in ("k1_std", "k2_std", "mean_std", "uncertain")}
    old = tmp_path / "old.csv"
    old.write_text("\n".join(",".join(v for i, v in enumerate(row) if i not in drop)
                             for row in rows) + "\n")
    back = read_result(old)
    assert np.isnan(back.k1_std).all() and np.isnan(back.mean_std).all()
    np.testing.assert_array_equal(back.uncertain, (res.status != 0).astype(np.uint8))
    np.testing.assert_array_equal(back.k1, res.k1)


def assert_same_result(a: CurvatureResult, b: CurvatureResult, faces=True):
    for name, value in a.fields().items():
        np.testing.assert_array_equal(b.fields()[name], value, err_msg=name)
    np.testing.assert_array_equal(b.points, a.points)
    if faces:
        np.testing.assert_array_equal(b.faces, a.faces)


# --- dispatch ------------------------------------------------------------------------------

def test_format_names_and_extension_dispatch():
    assert set(FORMATS_READ) == {"ply", "pcd", "xyz", "csv", "txt", "asc", "npy", "npz",
                                 "obj", "stl", "off", "glb", "gltf", "3mf", "las", "laz", "e57"}
    assert FORMATS_WRITE == ("ply", "csv", "npz", "json", "las", "laz")
    assert format_from_path("a/b/SCAN.PLY") == "ply"
    assert format_from_path("x.Json") == "json"
    assert curvature.read is read and curvature.write is write


def test_format_argument_overrides_extension(tmp_path):
    pts = np.random.default_rng(0).normal(size=(12, 3))
    path = tmp_path / "points.dat"
    write(path, pts, format="csv")
    np.testing.assert_array_equal(read(path, format="csv").points, pts)
    np.testing.assert_array_equal(read(path, format=".CSV").points, pts)


# --- writers: round trips -----------------------------------------------------------------

@pytest.mark.parametrize("binary", [True, False])
def test_result_ply_round_trip(tmp_path, binary):
    res = make_result()
    path = tmp_path / "res.ply"
    write(path, res, binary=binary)
    head = path.read_bytes()[:2000].split(b"end_header")[0].decode()
    assert ("binary_little_endian" in head) == binary
    names = [ln.split()[-1] for ln in head.splitlines() if ln.startswith("property ")]
    fields = ["k1", "k2", "mean", "gaussian", "d1x", "d1y", "d1z", "d2x", "d2y", "d2z",
              "residual", "neighbor_count", "status", "k1_std", "k2_std", "mean_std",
              "uncertain", "shape_index", "curvedness", "index"]
    # CloudCompare loads only standard names and scalar_*; MeshLab only quality.
    assert names == ["x", "y", "z", "nx", "ny", "nz", *(f"scalar_{f}" for f in fields),
                     "quality", "vertex_indices"]
    assert "property double scalar_residual" in head
    assert "property int scalar_neighbor_count" in head
    assert "property uchar scalar_status" in head
    assert "property uchar scalar_uncertain" in head
    assert "property double scalar_k1_std" in head
    assert "property list uchar int vertex_indices" in head
    cloud = read(path)
    assert set(cloud.properties) == set(fields)
    np.testing.assert_array_equal(cloud.points, res.points)
    np.testing.assert_array_equal(cloud.normals, res.normals)
    np.testing.assert_array_equal(cloud.properties["d2y"], res.dir2[:, 1])
    assert cloud.properties["status"].dtype == np.uint8
    assert cloud.properties["neighbor_count"].dtype == np.int32
    assert_same_result(res, read_result(path))


def test_result_csv_round_trip(tmp_path):
    res = make_result()
    path = tmp_path / "res.csv"
    write(path, res)
    lines = path.read_text().splitlines()
    assert lines[0] == ("x,y,z,nx,ny,nz,k1,k2,mean,gaussian,d1x,d1y,d1z,d2x,d2y,d2z,"
                        "residual,neighbor_count,status,k1_std,k2_std,mean_std,uncertain,"
                        "shape_index,curvedness,index")
    assert len(lines) == 31 and "nan" in lines[3].split(",")
    assert_same_result(res, read_result(path), faces=False)


def test_result_npz_round_trip(tmp_path):
    res = make_result()
    path = tmp_path / "res.npz"
    write(path, res)
    with np.load(path) as z:
        assert set(z.files) == {"points", "normals", "k1", "k2", "mean", "gaussian", "dir1",
                                "dir2", "residual", "neighbor_count", "status", "faces",
                                "k1_std", "k2_std", "mean_std", "uncertain",
                                "shape_index", "curvedness", "index"}
        assert z["dir1"].shape == (30, 3) and z["status"].dtype == np.uint8
    cloud = read(path)
    np.testing.assert_array_equal(cloud.properties["d1z"], res.dir1[:, 2])
    assert_same_result(res, read_result(path))


class WriteOnly:
    """A stream that can only be written to (like a web response)."""

    def __init__(self):
        self.chunks = []

    def write(self, data):
        self.chunks.append(bytes(data))
        return len(data)


@pytest.mark.parametrize("spool_bytes", [1 << 30, 64])  # in memory, spilled to disk
def test_npz_to_a_stream_that_cannot_seek(tmp_path, monkeypatch, spool_bytes):
    import io

    from curvature import io as cio

    monkeypatch.setattr(cio, "NPZ_SPOOL_BYTES", spool_bytes)
    res = make_result()
    stream = WriteOnly()
    cio.write_stream(stream, res, "npz")
    assert len(stream.chunks) >= 1
    path = tmp_path / "res.npz"
    write(path, res)  # a real file: written in place, no buffer
    with np.load(io.BytesIO(b"".join(stream.chunks))) as a, np.load(path) as b:
        assert a.files == b.files
        for name in a.files:
            np.testing.assert_array_equal(a[name], b[name])


def test_result_json(tmp_path):
    res = make_result()
    path = tmp_path / "res.json"
    write(path, res)
    def reject(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")

    doc = json.loads(path.read_text(), parse_constant=reject)
    assert doc["n"] == 30
    fields = doc["fields"]
    assert list(fields) == ["points", "normals", "k1", "k2", "mean", "gaussian", "dir1",
                            "dir2", "residual", "neighbor_count", "status", "k1_std",
                            "k2_std", "mean_std", "uncertain", "shape_index", "curvedness",
                            "index"]
    assert fields["k1_std"][2] is None and fields["k1_std"][0] == res.k1_std[0]
    assert fields["uncertain"] == res.uncertain.tolist()
    assert fields["k1"][2] is None and fields["k1"][0] == res.k1[0]
    assert fields["dir1"][7] == [None, None, None]
    assert fields["points"][5] == res.points[5].tolist()
    assert fields["status"][11] == 4 and fields["neighbor_count"] == res.neighbor_count.tolist()
    assert doc["faces"] == res.faces.tolist()
    assert doc["info"]["params"] == {"k": 24}


def test_result_json_numbers_read_back_exactly_across_blocks(monkeypatch):
    """Every number reads back bit for bit (float64 and float32 attributes, big-endian ones
    too), non-finite values are null, and blocks join with exactly one comma."""
    from curvature.io import json_format

    monkeypatch.setattr(json_format, "_CHUNK_ROWS", 7)  # 30 points: blocks of 7, 7, 7, 7, 2
    res = make_result()
    rng = np.random.default_rng(5)
    res.k2 = rng.normal(size=30) * 10.0 ** rng.integers(-150, 150, 30)
    res.k2[3], res.k2[4] = np.inf, -np.inf
    res.attributes["intensity"] = rng.random(30).astype(np.float32)
    res.attributes["height"] = rng.normal(size=30).astype(">f8")
    doc = json.loads(write_bytes(res, "json"))
    k2 = doc["fields"]["k2"]
    assert k2[3] is None and k2[4] is None and len(k2) == 30
    finite = np.isfinite(res.k2)
    np.testing.assert_array_equal(np.array(k2, dtype=object)[finite].astype(float),
                                  res.k2[finite])
    np.testing.assert_array_equal(np.float32(doc["fields"]["intensity"]),
                                  res.attributes["intensity"])
    np.testing.assert_array_equal(doc["fields"]["height"], res.attributes["height"])
    assert doc["fields"]["points"] == res.points.tolist()


def test_cloud_with_properties_round_trips_types(tmp_path):
    pts, quads = grid_mesh()
    n = len(pts)
    cloud = PointCloud(points=pts, normals=np.tile([0.0, 0.0, 1.0], (n, 1)),
                       faces=fan(quads), properties={
                           "intensity": np.linspace(0, 1, n).astype(np.float32),
                           "label": np.arange(n, dtype=np.uint8),
                           "count": np.arange(n, dtype=np.int64) - 5})
    for binary in (True, False):
        back = read_bytes(write_bytes(cloud, "ply", binary=binary), "ply")
        np.testing.assert_array_equal(back.points, pts)
        np.testing.assert_array_equal(back.faces, cloud.faces)
        assert back.properties["intensity"].dtype == np.float32
        np.testing.assert_array_equal(back.properties["intensity"],
                                      cloud.properties["intensity"])
        assert back.properties["label"].dtype == np.uint8
        assert back.properties["count"].dtype == np.int32  # PLY has no 64-bit ints
        np.testing.assert_array_equal(back.properties["count"], cloud.properties["count"])
    back = read_bytes(write_bytes(cloud, "npz"), "npz")
    np.testing.assert_array_equal(back.faces, cloud.faces)
    assert back.properties["count"].dtype == np.int64
    back = read_bytes(write_bytes(cloud, "csv"), "csv")
    np.testing.assert_array_equal(back.properties["label"], np.arange(n))


def test_number_texts_round_trip_exactly():
    from curvature.io.tokens import number_texts

    rng = np.random.default_rng(9)
    specials = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e-40, 3.4e38, 0.1, 1 / 3]
    for dtype in (np.float32, np.float64):
        values = np.concatenate([rng.normal(size=2000) * 10.0 ** rng.integers(-30, 30, 2000),
                                 specials]).astype(dtype)
        texts = number_texts(values)
        back = np.array(texts, dtype=np.float64).astype(dtype)
        np.testing.assert_array_equal(back, values)
        assert max(map(len, texts)) <= (16 if dtype == np.float32 else 24)
    assert number_texts(np.array([0.1, 2.5], dtype=np.float32)) == ["0.1", "2.5"]
    assert number_texts(np.array([-3, 7], dtype=np.int8)) == ["-3", "7"]
    assert number_texts(np.array([True, False])) == ["1", "0"]


def test_plain_array_every_write_format(tmp_path):
    pts = np.random.default_rng(1).normal(size=(15, 3)) * 1e3
    for fmt in FORMATS_WRITE:
        path = tmp_path / f"p.{fmt}"
        write(path, pts)
        if fmt == "json":
            assert json.loads(path.read_text())["fields"]["points"] == pts.tolist()
        elif fmt in ("las", "laz"):  # int32 coordinates, scaled
            np.testing.assert_allclose(read(path).points, pts, atol=1e-5)
        else:
            np.testing.assert_array_equal(read(path).points, pts)


def test_write_is_atomic_and_leaves_no_temp_files(tmp_path, monkeypatch):
    path = tmp_path / "out.ply"
    write(path, make_result())
    before = path.read_bytes()
    assert sorted(os.listdir(tmp_path)) == ["out.ply"]
    import curvature.io as cio

    def explode(fh, table, binary=True):
        fh.write(b"ply\nformat ascii 1.0\n")  # half a file ...
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(cio, "write_ply", explode)
    with pytest.raises(RuntimeError):
        write(path, make_result(n=12))
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["out.ply"]


def test_write_bytes_equals_file_and_stream(tmp_path):
    res = make_result()
    for fmt in ("ply", "csv", "json"):
        path = write(tmp_path / f"r.{fmt}", res)
        assert path.read_bytes() == write_bytes(res, fmt)

    class Sink:  # a non-seekable stream, like a web response body
        def __init__(self):
            self.parts = []

        def write(self, b):
            self.parts.append(bytes(b))
            return len(b)

    sink = Sink()
    write_stream(sink, res, "npz")
    assert_same_result(res, read_result_bytes(b"".join(sink.parts), "npz"))


def read_result_bytes(data, fmt):
    from curvature.io.columns import result_from_cloud

    return result_from_cloud(read_bytes(data, fmt))


def test_write_rejects_bad_objects(tmp_path):
    with pytest.raises(FormatError, match=r"shape \(n, 3\)"):
        write(tmp_path / "a.ply", np.zeros((10, 2)))
    bad = PointCloud(points=np.zeros((10, 3)), properties={"q": np.zeros(9)})
    with pytest.raises(FormatError, match="'q'"):
        write(tmp_path / "b.ply", bad)
    with pytest.raises(curvature.UnknownFormatError, match="cannot write"):
        write(tmp_path / "c.obj", np.zeros((10, 3)))
    assert os.listdir(tmp_path) == []


# --- PLY reader ----------------------------------------------------------------------------

VERTEX_PROPS = [("scalar", "uchar", "red"), ("scalar", "double", "z"),
                ("scalar", "short", "flags"), ("scalar", "float", "x"),
                ("scalar", "int8", "id"), ("scalar", "float64", "y"),
                ("scalar", "float", "nz"), ("scalar", "float", "nx"),
                ("scalar", "float32", "ny")]


def _vertex_rows(pts):
    return [(200 + i % 50, p[2], -3 * i, p[0], i - 5, p[1], 1.0, 0.0, 0.0)
            for i, p in enumerate(pts)]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_unusual_order_types_and_mixed_polygons(fmt):
    pts, quads = grid_mesh()
    polys = [quads[0][:3], quads[1], [0, 5, 10, 11, 6]] + quads[2:]
    elements = [
        ("vertex", VERTEX_PROPS, _vertex_rows(pts)),
        ("material", [("list", "uchar", "float", "rgb"), ("scalar", "int", "id")],
         [([0.1, 0.2], 1), ([], 2), ([1.0, 2.0, 3.0], 3)]),
        ("face", [("scalar", "uchar", "flag"), ("list", "ushort", "uint", "vertex_index"),
                  ("list", "uchar", "float", "texcoord")],
         [(7, p, [0.5] * (2 * len(p))) for p in polys]),
        ("trailer", [("scalar", "double", "t")], [(1.5,)]),
    ]
    cloud = read_bytes(build_ply(fmt, elements, comments=["made by a test"]), "ply",
                       source="mixed.ply")
    np.testing.assert_array_equal(cloud.points[:, 0], pts[:, 0].astype(np.float32))
    np.testing.assert_array_equal(cloud.points[:, 1:], pts[:, 1:])
    np.testing.assert_array_equal(cloud.normals, np.tile([0.0, 0.0, 1.0], (len(pts), 1)))
    np.testing.assert_array_equal(cloud.faces, fan(polys))
    assert cloud.properties["red"].dtype == np.uint8
    assert cloud.properties["flags"].dtype == np.int16
    assert cloud.properties["flags"][3] == -9 and cloud.properties["id"][0] == -5
    assert set(cloud.properties) == {"red", "flags", "id"}
    assert cloud.source == "mixed.ply"


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_constant_lists_with_extra_scalars(fmt):
    pts, quads = grid_mesh()
    tris = fan(quads)
    elements = [
        ("vertex", [("scalar", "float", "x"), ("scalar", "float", "y"),
                    ("scalar", "float", "z")], [tuple(p) for p in pts]),
        ("face", [("list", "int", "int", "vertex_indices"), ("scalar", "float", "quality")],
         [(t.tolist(), 0.5) for t in tris]),
    ]
    cloud = read_bytes(build_ply(fmt, elements), "ply")
    np.testing.assert_array_equal(cloud.faces, tris)
    assert cloud.normals is None
    np.testing.assert_array_equal(cloud.points, pts.astype(np.float32))


def test_ply_vertex_list_property_and_crlf_header():
    pts, _ = grid_mesh()
    rows = [(p[0], p[1], p[2], list(range(i % 3))) for i, p in enumerate(pts)]
    props = [("scalar", "double", "x"), ("scalar", "double", "y"), ("scalar", "double", "z"),
             ("list", "uchar", "int", "tags")]
    for fmt in ("ascii", "binary_little_endian"):
        data = build_ply(fmt, [("vertex", props, rows)])
        head, body = data.split(b"end_header\n", 1)
        data = head.replace(b"\n", b"\r\n") + b"end_header\r\n" + body
        if fmt == "ascii":
            data = data.replace(b"\n", b"\r\n").replace(b"\r\r\n", b"\r\n")
        cloud = read_bytes(data, "ply")
        np.testing.assert_array_equal(cloud.points, pts)
        assert cloud.properties == {}


def test_ply_ascii_and_binary_of_bunny_agree(shared_data):
    ascii_cloud = read(shared_data / "bun_zipper.ply")
    n, m = len(ascii_cloud), len(ascii_cloud.faces)
    dt = np.dtype([("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("confidence", ">f4"),
                   ("intensity", ">f4")])
    rec = np.empty(n, dtype=dt)
    for i, axis in enumerate("xyz"):
        rec[axis] = ascii_cloud.points[:, i]
    rec["confidence"] = ascii_cloud.properties["confidence"]
    rec["intensity"] = ascii_cloud.properties["intensity"]
    faces = np.empty(m, dtype=[("n", "u1"), ("v", ">i4", (3,))])
    faces["n"], faces["v"] = 3, ascii_cloud.faces
    head = (f"ply\nformat binary_big_endian 1.0\nelement vertex {n}\nproperty float x\n"
            "property float y\nproperty float z\nproperty float confidence\n"
            f"property float intensity\nelement face {m}\n"
            "property list uchar int vertex_indices\nend_header\n").encode()
    cloud = read_bytes(head + rec.tobytes() + faces.tobytes(), "ply")
    np.testing.assert_array_equal(cloud.points, ascii_cloud.points)
    np.testing.assert_array_equal(cloud.faces, ascii_cloud.faces)
    np.testing.assert_array_equal(cloud.properties["intensity"],
                                  ascii_cloud.properties["intensity"])


# --- PCD reader ----------------------------------------------------------------------------

def _pcd_cloud(width=6, height=4):
    rng = np.random.default_rng(5)
    n = width * height
    xyz = rng.normal(size=(n, 3)).astype(np.float32)
    xyz[[1, 9, 17]] = np.nan
    xyz[4, 2] = np.nan
    normals = rng.normal(size=(n, 3)).astype(np.float32)
    rgb = rng.integers(0, 2**24, n).astype(np.uint32)
    hist = rng.integers(-100, 100, size=(n, 2)).astype(np.int16)
    return xyz, normals, rgb, hist


def build_pcd(kind, width=6, height=4):
    xyz, normals, rgb, hist = _pcd_cloud(width, height)
    n = width * height
    head = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
            "FIELDS x y z normal_x normal_y normal_z rgb hist\nSIZE 4 4 4 4 4 4 4 2\n"
            "TYPE F F F F F F F I\nCOUNT 1 1 1 1 1 1 1 2\n"
            f"WIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
            f"DATA {kind}\n").encode()
    rgb_f = rgb.view(np.float32)
    if kind == "ascii":
        lines = []
        for i in range(n):
            vals = [repr(float(v)) for v in (*xyz[i], *normals[i])]
            vals.append(f"{float(rgb_f[i]):.9g}")
            vals += [str(int(v)) for v in hist[i]]
            lines.append(" ".join(vals))
        return head + ("\n".join(lines) + "\n").encode()
    cols = [xyz[:, 0], xyz[:, 1], xyz[:, 2], normals[:, 0], normals[:, 1], normals[:, 2],
            rgb_f, hist]
    if kind == "binary":
        dt = np.dtype([(f"f{i}", "<f4") for i in range(7)] + [("h", "<i2", (2,))])
        rec = np.empty(n, dtype=dt)
        for i in range(7):
            rec[f"f{i}"] = cols[i]
        rec["h"] = hist
        return head + rec.tobytes()
    raw = b"".join(np.ascontiguousarray(c).astype(c.dtype.newbyteorder("<")).tobytes()
                   for c in cols)
    packed = lzf_compress(raw)
    return head + struct.pack("<II", len(packed), len(raw)) + packed


@pytest.mark.parametrize("kind", ["ascii", "binary", "binary_compressed"])
def test_pcd_kinds_drop_nan_rows_and_keep_fields(kind):
    xyz, normals, rgb, hist = _pcd_cloud()
    keep = np.isfinite(xyz).all(axis=1)
    cloud = read_bytes(build_pcd(kind), "pcd", source="t.pcd")
    assert cloud.dropped == 4 and len(cloud) == 20
    np.testing.assert_array_equal(cloud.points, xyz[keep].astype(np.float64))
    np.testing.assert_array_equal(cloud.normals, normals[keep].astype(np.float64))
    np.testing.assert_array_equal(cloud.properties["rgb"], rgb[keep])
    assert cloud.properties["rgb"].dtype == np.uint32
    np.testing.assert_array_equal(cloud.properties["hist_1"], hist[keep, 1])
    assert set(cloud.properties) == {"rgb", "hist_0", "hist_1"}


def test_lzf_decoder_round_trips_and_rejects_corruption():
    rng = np.random.default_rng(2)
    parts = [bytes(300), rng.integers(0, 256, 500, dtype=np.uint8).tobytes(),
             b"abcabcabcabc" * 40, bytes(range(256)) * 3, b"x"]
    data = b"".join(parts)
    packed = lzf_compress(data)
    assert len(packed) < len(data) * 0.7  # back references were really used
    assert lzf_decompress(packed, len(data)).tobytes() == data
    literal_only = bytes([4]) + b"hello" + bytes([0]) + b"!"
    assert lzf_decompress(literal_only, 6).tobytes() == b"hello!"
    overlap = bytes([0]) + b"a" + bytes([(3 << 5) | 0, 0])  # 'a' then copy 5 from 1 back
    assert lzf_decompress(overlap, 6).tobytes() == b"aaaaaa"
    with pytest.raises(LZFError, match="before the start"):
        lzf_decompress(bytes([0]) + b"a" + bytes([(1 << 5), 5]), 4)
    with pytest.raises(LZFError, match="past the end"):
        lzf_decompress(bytes([9]) + b"abc", 10)
    with pytest.raises(LZFError, match="fewer bytes"):
        lzf_decompress(packed, len(data) + 1)
    with pytest.raises(LZFError, match="more bytes"):
        lzf_decompress(packed, len(data) - 1)
    with pytest.raises(LZFError, match="cannot expand"):
        lzf_decompress(b"\x00a", 10**9)


# --- text, numpy and mesh readers ---------------------------------------------------------

def _pts(n=12, seed=4):
    return np.round(np.random.default_rng(seed).normal(size=(n, 3)), 6)


@pytest.mark.parametrize("sep", [" ", "\t", ",", ";", ", "])
@pytest.mark.parametrize("ext", ["xyz", "csv", "txt", "asc"])
def test_text_separators(sep, ext):
    pts = _pts()
    body = "\n".join(sep.join(repr(float(v)) for v in p) for p in pts)
    data = ("# scanner export\n\n" + body + "\r\n").encode()
    cloud = read_bytes(data, ext)
    np.testing.assert_array_equal(cloud.points, pts)
    assert cloud.normals is None


def test_text_six_columns_header_and_decimal_comma():
    pts = _pts()
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    rows = np.hstack([pts, nrm])
    text = "X,Y,Z,NX,NY,NZ\n" + "\n".join(",".join(map(repr, r.tolist())) for r in rows)
    cloud = read_bytes(text.encode(), "csv")
    np.testing.assert_array_equal(cloud.points, pts)
    np.testing.assert_array_equal(cloud.normals, nrm)
    plain = "\n".join(" ".join(map(repr, r.tolist())) for r in rows)
    np.testing.assert_array_equal(read_bytes(plain.encode(), "xyz").normals, nrm)
    euro = "\n".join(";".join(repr(v).replace(".", ",") for v in p.tolist()) for p in pts)
    np.testing.assert_array_equal(read_bytes(euro.encode(), "csv").points, pts)


def test_npy_shapes_and_structured(tmp_path):
    pts = _pts()
    for arr in (pts, np.hstack([pts, pts]), pts.astype(np.float32)):
        path = tmp_path / "a.npy"
        np.save(path, arr)
        cloud = read(path)
        np.testing.assert_array_equal(cloud.points, arr[:, :3].astype(np.float64))
        assert (cloud.normals is None) == (arr.shape[1] == 3)
    np.save(tmp_path / "f.npy", np.asfortranarray(pts))
    np.testing.assert_array_equal(read(tmp_path / "f.npy").points, pts)
    rec = np.zeros(len(pts), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("i", "u2")])
    rec["x"], rec["y"], rec["z"], rec["i"] = pts[:, 0], pts[:, 1], pts[:, 2], 7
    np.save(tmp_path / "s.npy", rec)
    cloud = read(tmp_path / "s.npy")
    np.testing.assert_array_equal(cloud.points, pts)
    assert cloud.properties["i"].tolist() == [7] * len(pts)


def test_npz_hand_made(tmp_path):
    pts, quads = grid_mesh()
    np.savez(tmp_path / "m.npz", points=pts, normals=pts * 0 + 1, faces=fan(quads),
             weight=np.arange(len(pts)))
    cloud = read(tmp_path / "m.npz")
    np.testing.assert_array_equal(cloud.faces, fan(quads))
    np.testing.assert_array_equal(cloud.properties["weight"], np.arange(len(pts)))


def test_obj_slash_syntax_negative_indices_and_normals():
    pts, quads = grid_mesh()
    lines = ["# exported", "mtllib x.mtl", "o grid"]
    lines += [f"v {p[0]!r} {p[1]!r} {p[2]!r}" for p in pts.tolist()]
    lines += ["vn 0 0 1", "vn 0 1 0", "vt 0.5 0.5"]
    n = len(pts)
    a, b, c, d = quads[0]
    lines.append(f"f {a + 1}/1/1 {b + 1}/1/1 {c + 1}/1/1 {d + 1}/1/1")
    a, b, c, d = quads[1]
    lines.append(f"f {a - n}//-1 {b - n}//-1 {c - n}//-1")  # negative: relative to end
    lines += ["usemtl m", "s off"]
    lines += [f"f {q[0] + 1}/1 {q[1] + 1}/1 {q[2] + 1}/1 {q[3] + 1}/1" for q in quads[2:]]
    lines.append("  f 1 2 3")
    cloud = read_bytes("\n".join(lines).encode(), "obj")
    expected = fan([quads[0], quads[1][:3]] + quads[2:] + [[0, 1, 2]])
    np.testing.assert_array_equal(cloud.points, pts)
    np.testing.assert_array_equal(cloud.faces, expected)
    # vertices 1, 2, 7 are paired with vn 2 by a later face: the last pairing wins
    np.testing.assert_array_equal(cloud.normals[[0, 5, 6]], np.tile([0, 0, 1.0], (3, 1)))
    np.testing.assert_array_equal(cloud.normals[[1, 2, 7]], np.tile([0, 1.0, 0], (3, 1)))
    assert np.isnan(cloud.normals[n - 1]).all()


def _stl_ascii(pts, tris):
    out = ["solid grid"]
    for t in tris:
        out += ["  facet normal 0 0 1", "    outer loop"]
        out += [f"      vertex {pts[i][0]!r} {pts[i][1]!r} {pts[i][2]!r}" for i in t]
        out += ["    endloop", "  endfacet"]
    out.append("endsolid grid")
    return "\n".join(out).encode()


def _stl_binary(pts, tris, header=b"binary stl"):
    rec = np.zeros(len(tris), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)),
                                     ("a", "<u2")])
    rec["v"] = pts[tris]
    return header.ljust(80, b" ") + struct.pack("<I", len(tris)) + rec.tobytes()


@pytest.mark.parametrize("kind", ["ascii", "binary", "binary_solid_header"])
def test_stl_merges_shared_vertices(kind):
    pts, quads = grid_mesh()
    pts = pts.astype(np.float32).astype(np.float64)
    tris = fan(quads)
    if kind == "ascii":
        data = _stl_ascii(pts.tolist(), tris)
    else:
        header = b"solid but binary" if kind == "binary_solid_header" else b"binary stl"
        data = _stl_binary(pts, tris, header)
    cloud = read_bytes(data, "stl")
    assert len(cloud) == len(pts)  # 3 corners per triangle merged back to the grid
    np.testing.assert_array_equal(cloud.points[cloud.faces], pts[tris])
    first_seen = list(dict.fromkeys(tris.ravel().tolist()))
    np.testing.assert_array_equal(cloud.points, pts[first_seen])  # first-appearance order


def test_off_variants():
    pts, quads = grid_mesh()
    body = [" ".join(map(repr, p)) for p in pts.tolist()]
    faces = [f"{len(q)} " + " ".join(map(str, q)) + " 255 0 0" for q in quads]
    text = "OFF\n# comment\n" + f"{len(pts)} {len(quads)} 0\n" + "\n".join(body + faces)
    cloud = read_bytes(text.encode(), "off")
    np.testing.assert_array_equal(cloud.points, pts)
    np.testing.assert_array_equal(cloud.faces, fan(quads))
    nbody = [b + " 0 0 1" for b in body]
    text = f"NOFF {len(pts)} {len(quads)} 0\n" + "\n".join(nbody + faces)
    cloud = read_bytes(text.encode(), "off")
    np.testing.assert_array_equal(cloud.normals, np.tile([0, 0, 1.0], (len(pts), 1)))


# --- real scans ----------------------------------------------------------------------------

REAL = {
    "bun000.ply": (40256, None, 0),
    "bun_zipper.ply": (35947, 69451, 0),
    "table_scene_mug_stereo_textured.pcd": (209280, None, 97920),
    "milk_cartoon_all_small_clorox.pcd": (241407, None, 307200 - 241407),
}


@pytest.mark.parametrize("name", list(REAL))
def test_real_scans_load(shared_data, name):
    n, m, dropped = REAL[name]
    cloud = read(shared_data / name)
    assert len(cloud) == n and cloud.dropped == dropped
    assert cloud.points.dtype == np.float64 and np.isfinite(cloud.points).all()
    assert (cloud.faces is None) if m is None else cloud.faces.shape == (m, 3)
    assert cloud.source == str(shared_data / name)
    if name == "bun_zipper.ply":
        assert set(cloud.properties) == {"confidence", "intensity"}
        assert cloud.faces.max() == n - 1 and cloud.faces.min() == 0
    if name == "bun000.ply":
        np.testing.assert_allclose(cloud.points.min(axis=0), [-0.09475, 0.03574, -0.0587],
                                   atol=1e-5)
    if name.endswith(".pcd"):
        assert set(cloud.properties) == {"rgba"}
        assert 0.5 < cloud.points[:, 2].min() and cloud.points[:, 2].max() < 2.6


def _py_lzf_prefix(block: bytes) -> bytes:
    """Plain-Python LZF decoding of the complete runs at the start of ``block``."""
    out, i = bytearray(), 0
    while i < len(block):
        ctrl = block[i]
        if ctrl < 32:
            if i + 1 + ctrl + 1 > len(block):
                break
            out += block[i + 1:i + 2 + ctrl]
            i += ctrl + 2
            continue
        length, head = ctrl >> 5, 2
        if length == 7:
            if i + 2 >= len(block):
                break
            length += block[i + 1]
            head = 3
        if i + head > len(block):
            break
        ref = len(out) - ((ctrl & 31) << 8) - 1 - block[i + head - 1]
        for k in range(length + 2):
            out.append(out[ref + k])
        i += head
    return bytes(out)


@pytest.mark.parametrize("name, lo, hi", [
    ("milk_cartoon_all_small_clorox.pcd", [-1.0608, -0.86923, 0.501], [1.15249, 0.21967, 2.063]),
    ("table_scene_mug_stereo_textured.pcd", [-0.45643, -0.51074, 0.69001],
     [0.71518, 0.17923, 2.5927]),
])
def test_real_pcd_decoding_is_right(shared_data, name, lo, hi):
    data = (shared_data / name).read_bytes()
    start = data.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    csize, usize = struct.unpack_from("<II", data, start)
    block = data[start + 8:start + 8 + csize]
    ours = lzf_decompress(block, usize).tobytes()
    assert len(ours) == usize == 307200 * 16
    prefix = _py_lzf_prefix(block[:20000])
    assert len(prefix) > 20000 and ours.startswith(prefix)
    cloud = read(shared_data / name)
    xyz = np.frombuffer(ours, "<f4", 3 * 307200).reshape(3, -1).T  # column-major fields
    np.testing.assert_array_equal(cloud.points, xyz[np.isfinite(xyz).all(axis=1)])
    # bounding box printed by the independent check_scans.py (README.md)
    np.testing.assert_allclose(cloud.points.min(axis=0), lo, atol=1e-5)
    np.testing.assert_allclose(cloud.points.max(axis=0), hi, atol=1e-5)


def test_result_ply_of_real_scan_size_cloud(tmp_path, shared_data):
    cloud = read(shared_data / "bun_zipper.ply")
    path = write(tmp_path / "b.ply", cloud)
    back = read(path)
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_array_equal(back.faces, cloud.faces)
    np.testing.assert_array_equal(back.properties["confidence"],
                                  cloud.properties["confidence"])
