"""curvature.io: every malformed input ends as a FormatError naming the file and the place."""

from __future__ import annotations

import io
import struct
import tracemalloc

import numpy as np
import pytest

from curvature.cloud import PointCloud
from curvature.errors import FormatError, UnknownFormatError
from curvature.io import FORMATS_READ, format_from_path, read, read_bytes, write_bytes
from curvature.validation import MIN_POINTS

SRC = "bad.file"


def points(n=12, seed=0):
    return np.round(np.random.default_rng(seed).normal(size=(n, 3)), 5)


def ascii_ply(pts, faces=(), extra_header="", vertex_count=None, face_count=None):
    n = len(pts) if vertex_count is None else vertex_count
    head = ["ply", "format ascii 1.0", f"element vertex {n}", "property float x",
            "property float y", "property float z"]
    if faces or face_count is not None:
        head += [f"element face {len(faces) if face_count is None else face_count}",
                 "property list uchar int vertex_indices"]
    head += [extra_header] if extra_header else []
    head.append("end_header")
    body = [" ".join(map(str, p)) for p in np.asarray(pts).tolist()]
    body += [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    return ("\n".join(head + body) + "\n").encode()


def binary_ply(pts, faces=None, order="<", vertex_count=None):
    n = len(pts) if vertex_count is None else vertex_count
    head = ["ply", f"format binary_{'little' if order == '<' else 'big'}_endian 1.0",
            f"element vertex {n}", "property float x", "property float y", "property float z"]
    body = np.asarray(pts, dtype=order + "f4").tobytes()
    if faces is not None:
        head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
        for f in faces:
            body += struct.pack(order + "B" + "i" * len(f), len(f), *f)
    return ("\n".join(head) + "\nend_header\n").encode() + body


def pcd(kind, pts, *, points_line=None, width=None, extra=""):
    n = len(pts)
    head = (f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n{extra}"
            f"WIDTH {n if width is None else width}\nHEIGHT 1\n"
            f"POINTS {n if points_line is None else points_line}\nDATA {kind}\n").encode()
    arr = np.asarray(pts, dtype="<f4")
    if kind == "ascii":
        return head + "\n".join(" ".join(map(repr, p)) for p in arr.tolist()).encode()
    if kind == "binary":
        return head + arr.tobytes()
    raw = arr.T.tobytes()  # column-major fields
    packed = b"".join(bytes([len(raw[i:i + 32]) - 1]) + raw[i:i + 32]
                      for i in range(0, len(raw), 32))  # literal-only LZF
    return head + struct.pack("<II", len(packed), len(raw)) + packed


def err(data, fmt, match=None) -> FormatError:
    with pytest.raises(FormatError, match=match) as info:
        read_bytes(data, fmt, source=SRC)
    assert str(info.value).startswith(SRC)
    return info.value


# --- names, empty files, too few points ---------------------------------------------------

def test_unknown_extension(tmp_path):
    path = tmp_path / "scan.rcs"
    path.write_bytes(b"whatever")
    with pytest.raises(UnknownFormatError, match=r"scan\.rcs.*'\.rcs'.*ply"):
        read(path)
    with pytest.raises(UnknownFormatError, match="no extension"):
        format_from_path("README")
    with pytest.raises(UnknownFormatError, match="cannot read format 'rcs'"):
        read_bytes(b"x", "rcs")
    assert issubclass(UnknownFormatError, FormatError) and issubclass(FormatError, ValueError)


@pytest.mark.parametrize("fmt", FORMATS_READ)
def test_empty_file(tmp_path, fmt):
    path = tmp_path / f"empty.{fmt}"
    path.write_bytes(b"")
    with pytest.raises(FormatError, match="empty") as info:
        read(path)
    assert info.value.path == str(path) and str(path) in str(info.value)


def _five_point_files():
    pts = points(5)
    tris = [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    obj = "\n".join([f"v {a} {b} {c}" for a, b, c in pts.tolist()] + ["f 1 2 3"])
    off = "OFF\n5 1 0\n" + "\n".join(" ".join(map(str, p)) for p in pts.tolist()) + "\n3 0 1 2"
    stl = np.zeros(3, dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    stl["v"] = pts[tris]
    npy, npz = io.BytesIO(), io.BytesIO()
    np.save(npy, pts)
    np.savez(npz, points=pts)
    return {
        "ply": ascii_ply(pts), "xyz": "\n".join(" ".join(map(str, p)) for p in
                                                pts.tolist()).encode(),
        "pcd": pcd("binary", pts), "obj": obj.encode(), "off": off.encode(),
        "stl": b"x" * 80 + struct.pack("<I", 3) + stl.tobytes(),
        "npy": npy.getvalue(), "npz": npz.getvalue(),
    }


@pytest.mark.parametrize("fmt", ["ply", "xyz", "pcd", "obj", "off", "stl", "npy", "npz"])
def test_five_points_is_too_few(fmt):
    e = err(_five_point_files()[fmt], fmt)
    assert f"only 5 points, at least {MIN_POINTS} are needed" in str(e)


def test_pcd_all_nan_and_few_finite():
    pts = points(20)
    pts[5:] = np.nan
    assert "only 5 points" in str(err(pcd("binary", pts), "pcd"))
    pts[:] = np.nan
    err(pcd("binary", pts), "pcd", "all 20 points have a NaN")


# --- PLY ----------------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_without_vertices(fmt):
    data = (f"ply\nformat {fmt} 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
            "property float z\nend_header\n").encode()
    assert err(data, "ply", "holds no points").line == 3


def test_truncated_binary_ply_names_offset():
    pts = points(20)
    data = binary_ply(pts, [[0, 1, 2], [2, 3, 4, 5]])
    body = data.index(b"end_header\n") + 11
    for cut in (body + 7, body + 20 * 12 - 1, body + 20 * 12 + 3, len(data) - 1):
        e = err(data[:cut], "ply")
        assert e.offset is not None and e.offset <= cut
        assert "truncated" in e.reason or "ends inside" in e.reason


def test_header_count_larger_than_body():
    e = err(binary_ply(points(20), vertex_count=25), "ply", "header says 25 vertex rows")
    assert e.offset is not None
    e = err(ascii_ply(points(20), vertex_count=30), "ply", "30 vertex rows")
    # ascii: a count smaller than the rows present makes the faces read vertex lines
    e = err(ascii_ply(points(20), [[0, 1, 2]], vertex_count=15), "ply",
            r"face row 0: list length -0\.31392 of 'vertex_indices' is not")
    assert e.line == 9 + 15 + 1  # 9 header lines, then 15 'vertex' rows


@pytest.mark.parametrize("make", [
    lambda: ascii_ply(points(12), vertex_count=10**12),
    lambda: binary_ply(points(12), vertex_count=10**12),
    lambda: ascii_ply(points(12), [[0, 1, 2]], face_count=10**12),
    lambda: pcd("binary", points(12), points_line=10**12, width=10**12),
    lambda: pcd("ascii", points(12), points_line=10**12, width=10**12),
    lambda: pcd("binary_compressed", points(12), points_line=10**12, width=10**12),
    lambda: f"OFF\n{10**12} 1 0\n0 0 0\n".encode(),
    lambda: b"x" * 80 + struct.pack("<I", 2**32 - 1) + bytes(100),
    lambda: b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_order': False, 'shape': "
            b"(1000000000000, 3), }".ljust(118) + b"\n" + bytes(64),
], ids=["ply-ascii", "ply-binary", "ply-faces", "pcd-binary", "pcd-ascii", "pcd-lzf", "off",
        "stl", "npy"])
def test_huge_header_counts_fail_fast_without_allocating(make):
    data = make()
    fmt = {b"ply": "ply", b"VER": "pcd", b"OFF": "off", b"xxx": "stl",
           b"\x93NU": "npy"}[data[:3]]
    tracemalloc.start()
    try:
        e = err(data, fmt)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 2_000_000, f"{peak} bytes allocated for a {len(data)}-byte file"
    assert "10000000000" in str(e) or "4294967295" in str(e) or "bytes" in str(e)


@pytest.mark.parametrize("data, match, line", [
    (b"plx\nformat ascii 1.0\n", "must start with the line 'ply'", 1),
    (b"ply\nformat ascii 1.0\nelement vertex 3\n", "no 'end_header'", None),
    (b"ply\nformat ascii 2 1.0\nend_header\n", "bad format line", 2),
    (b"ply\nformat ebcdic 1.0\nend_header\n", "bad format line", 2),
    (b"ply\nelement vertex 3\nend_header\n", "no 'format' line", None),
    (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "before any element", 3),
    (b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", "bad element line", 3),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty real x\nend_header\n",
     "unknown PLY type 'real'", 4),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty list float int x\nend_header\n",
     "must be an integer type", 4),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float x\n"
     b"end_header\n", "declared twice", 5),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     b"end_header\n", "no scalar property 'z'", 3),
    (b"ply\nformat ascii 1.0\nelement face 3\nproperty float x\nend_header\n",
     "no 'vertex' element", None),
    (b"ply\nformat ascii 1.0\nelemnt vertex 3\nend_header\n", "unknown keyword 'elemnt'", 3),
])
def test_garbled_ply_headers(data, match, line):
    assert err(data, "ply", match).line == line


def test_ply_ascii_body_errors_name_the_line():
    good = ascii_ply(points(12), [[0, 1, 2], [3, 4, 5, 6]])
    lines = good.decode().split("\n")
    first_vertex = lines.index("end_header") + 2  # 1-based line number

    def with_line(k, text):
        copy = list(lines)
        copy[k - 1] = text
        return "\n".join(copy).encode()

    e = err(with_line(first_vertex + 3, "1 2"), "ply", "vertex row 3: 2 values, expected 3")
    assert e.line == first_vertex + 3 and f"line {first_vertex + 3}" in str(e)
    e = err(with_line(first_vertex + 4, "1 2 abc"), "ply", "'abc' is not a number")
    assert e.line == first_vertex + 4
    e = err(with_line(first_vertex + 5, "1 nan 2"), "ply", "vertex 5 has a NaN")
    assert e.line == first_vertex + 5
    face_line = first_vertex + 12
    assert err(with_line(face_line, "4 0 1 2"), "ply", "only 3 values follow").line == face_line
    e = err(with_line(face_line + 1, "3 0 1 2 9"), "ply", "5 values, but its properties")
    assert e.line == face_line + 1
    e = err(with_line(face_line, "-1 0 1 2"), "ply", "not a non-negative integer")
    assert e.line == face_line
    e = err(with_line(face_line, "3 0 1.5 2"), "ply", "expected integers")
    assert e.line == face_line


@pytest.mark.parametrize("kind", ["ascii", "binary", "binary_variable"])
def test_ply_bad_face_index(kind):
    pts = points(12)
    faces = [[0, 1, 2], [3, 4, 12]]
    if kind == "binary_variable":
        faces = [[0, 1, 2, 3], [3, 4, -1]]
    data = ascii_ply(pts, faces) if kind == "ascii" else binary_ply(pts, faces)
    e = err(data, "ply", r"face 1 refers to vertex (12|-1), but there are only 12 vertices")
    if kind == "ascii":
        assert e.line == data.decode().split("\n").index("end_header") + 1 + 12 + 2
    else:
        body = data.index(b"end_header\n") + 11
        assert e.offset == body + 12 * 12 + (13 if kind == "binary" else 17)


def test_ply_binary_inf_coordinate_names_offset():
    pts = points(12)
    pts[4, 1] = np.inf
    data = binary_ply(pts, order=">")
    e = err(data, "ply", "vertex 4 has a NaN or Inf")
    assert e.offset == data.index(b"end_header\n") + 11 + 4 * 12


def test_ply_missing_face_list_and_negative_binary_count():
    data = ascii_ply(points(12)).replace(
        b"end_header", b"element face 1\nproperty list uchar int corners\nend_header")
    data += b"3 0 1 2\n"
    err(data, "ply", "no 'vertex_indices'")
    pts = points(12)
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 12\nproperty float x\n"
            b"property float y\nproperty float z\nelement face 2\n"
            b"property list char int vertex_indices\nend_header\n")
    body = pts.astype("<f4").tobytes() + struct.pack("<bi", 1, 0) + struct.pack("<b", -2)
    e = err(head + body + bytes(8), "ply", "face row 1 has a negative list length")
    assert e.offset == len(head) + 12 * 12 + 5


# --- text ---------------------------------------------------------------------------------

def test_xyz_wrong_column_count_names_the_line():
    rows = [" ".join(map(str, p)) for p in points(12).tolist()]
    rows[5] += " 7"
    text = "# comment line\n\n" + "\n".join(rows)
    e = err(text.encode(), "xyz", "4 columns, expected 3 like the first row")
    assert e.line == 8 and "line 8" in str(e)
    e = err(b"1 2 3 4\n" * 12, "xyz", r"4 columns, expected 3 \(x y z\) or 6")
    assert e.line == 1
    e = err(b"x,y,z\n1,2\n", "csv", "header names 3 columns but the first row has 2")
    assert e.line == 1


def test_xyz_nan_and_text_tokens_name_the_line():
    rows = [" ".join(map(str, p)) for p in points(12).tolist()]
    rows[9] = "1.0 NaN 2.0"
    e = err("\n".join(rows).encode(), "xyz", "row 9 has a NaN or Inf coordinate")
    assert e.line == 10
    rows[9] = "1.0 inf 2.0"
    assert err("\n".join(rows).encode(), "txt").line == 10
    rows[9] = "1.0 2.0 3.0.0"
    e = err("\n".join(rows).encode(), "asc", "'3.0.0' is not a number")
    assert e.line == 10
    rows[9] = "1,,3"
    assert err("\n".join(rows).encode(), "csv").line == 10


def test_text_not_utf8_and_header_only():
    e = err(b"1 2 3\n\xff\xfe 4 5\n", "xyz", "not valid UTF-8")
    assert e.offset == 6
    err(b"x y z\n", "xyz", "header line but no points")
    err(b"# only a comment\n\n", "csv", "no points")
    err(b"a b c d\n1 2 3 4\n", "xyz", "does not name x, y and z")


# --- PCD ----------------------------------------------------------------------------------

@pytest.mark.parametrize("data, match", [
    (b"HELLO 1\n", "not a PCD file: unknown keyword 'HELLO'"),
    (b"VERSION 0.7\nFIELDS x y z\n", "no DATA line"),
    (b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n",
     "SIZE has 2 entries but FIELDS has 3"),
    (b"FIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nWIDTH 1\nDATA ascii\n", "unsupported TYPE F"),
    (b"FIELDS x y w\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA ascii\n", "no 'z' field"),
    (b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 4\nHEIGHT 3\nPOINTS 10\nDATA ascii\n",
     "WIDTH x HEIGHT = 4 x 3 = 12 but POINTS = 10"),
    (b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nDATA zip\n", "DATA must be"),
    (b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH a\nDATA ascii\n", "WIDTH values must"),
    (b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nDATA ascii\n", "no WIDTH line"),
])
def test_garbled_pcd_headers(data, match):
    err(data, "pcd", match)


def test_pcd_body_errors():
    pts = points(12)
    e = err(pcd("binary", pts)[:-5], "pcd", "only 139 bytes follow")
    assert e.offset is not None
    data = pcd("ascii", pts)
    lines = data.decode().split("\n")
    lines[9 + 3] = "1 2"
    e = err("\n".join(lines).encode(), "pcd", "point 3 has 2 values, expected 3")
    assert e.line == 13
    lines[9 + 3] = "1 2 x"
    assert err("\n".join(lines).encode(), "pcd", "'x' is not a number").line == 13
    err(pcd("ascii", pts, points_line=13, width=13), "pcd", "only 12 data lines")
    good = pcd("binary_compressed", pts)
    start = good.index(b"DATA binary_compressed\n") + 23
    err(good[:start + 5], "pcd", "no size words")
    err(good[:-1], "pcd", "claims 149 bytes but only 148 follow")
    bad_size = good[:start + 4] + struct.pack("<I", 10) + good[start + 8:]
    e = err(bad_size, "pcd", "unpacks to 10 bytes but 12 points of 12 bytes need 144")
    assert e.offset == start + 4
    corrupt = bytearray(good)
    corrupt[start + 8 + 33] = 0xE0  # a back reference as the second run, 8 KiB back
    e = err(bytes(corrupt), "pcd", "corrupt LZF data: a back reference points before")
    assert e.offset == start + 8 + 33


# --- numpy --------------------------------------------------------------------------------

def test_numpy_file_errors():
    buf = io.BytesIO()
    np.save(buf, points(12))
    good = buf.getvalue()
    err(good[:-8], "npy", r"shape \(12, 3\) \(288 bytes\) but only 280")
    err(b"\x93NUMPX" + good[6:], "npy", "garbled .npy header")
    buf = io.BytesIO()
    np.save(buf, np.zeros((12, 4)))
    err(buf.getvalue(), "npy", r"shape \(12, 4\), expected \(n, 3\) or \(n, 6\)")
    buf = io.BytesIO()
    np.save(buf, np.array([None] * 12, dtype=object), allow_pickle=True)
    err(buf.getvalue(), "npy", "Python objects")
    pts = points(12)
    pts[3, 0] = np.nan
    buf = io.BytesIO()
    np.save(buf, pts)
    err(buf.getvalue(), "npy", "row 3 has a NaN")
    err(b"PK\x03\x04 not really", "npz", "not a valid .npz")
    buf = io.BytesIO()
    np.savez(buf, pts=points(12))
    err(buf.getvalue(), "npz", r"no 'points' array \(found: \['pts'\]\)")
    buf = io.BytesIO()
    np.savez(buf, points=points(12), faces=np.array([[0, 1, 12]]))
    err(buf.getvalue(), "npz", "face 0 refers to vertex 12")
    buf = io.BytesIO()
    np.savez(buf, points=points(12), normals=np.zeros((11, 3)))
    err(buf.getvalue(), "npz", r"'normals' has shape \(11, 3\)")


# --- meshes -------------------------------------------------------------------------------

def _obj(pts, faces_text):
    return ("\n".join(f"v {a} {b} {c}" for a, b, c in pts.tolist()) + "\n" + faces_text).encode()


def test_obj_errors_name_the_line():
    pts = points(12)
    e = err(_obj(pts, "f 1 2 3\nf 1 2 13"), "obj", "face 1 refers to vertex 12")
    assert e.line == 14
    assert err(_obj(pts, "f 1 0 3"), "obj", "index 0").line == 13
    assert err(_obj(pts, "f 1 -13 3"), "obj", "refers to vertex -1").line == 13
    assert err(_obj(pts, "f 1 2 x/1"), "obj", "'x' is not an integer").line == 13
    assert err(_obj(pts, "f 1//1 2//1 3//1"), "obj", "normal 1 but only 0 'vn'").line == 13
    assert err(_obj(pts, "v 1 2\n"), "obj", "needs 3 numbers").line == 13
    pts[2, 2] = np.nan
    assert err(_obj(pts, ""), "obj", "vertex 2 has a NaN").line == 3


def test_stl_errors():
    e = err(b"binary but far too short", "stl", "too short for a binary STL")
    assert e.offset == 24
    e = err(b"x" * 80 + struct.pack("<I", 3) + bytes(100), "stl", "header says 3 triangles")
    assert e.offset == 184
    text = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
            "endloop\nendfacet\nendsolid t\n")
    e = err(text.encode(), "stl", "expected 'vertex' in ascii STL, found 'endloop'")
    assert e.line == 6
    text = text.replace("vertex 1 0 0\n", "vertex 1 0 0\nvertex 1 nan 0\n")
    assert err(text.encode(), "stl", "triangle 0 has a NaN").line == 6
    rec = np.zeros(4, dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = np.arange(36).reshape(4, 3, 3)
    rec["v"][2, 1, 2] = np.inf
    e = err(b"x" * 80 + struct.pack("<I", 4) + rec.tobytes(), "stl", "triangle 2")
    assert e.offset == 84 + 2 * 50 + 12 + 12


def test_off_errors():
    body = "\n".join(" ".join(map(str, p)) for p in points(12).tolist())
    assert err(b"PLY\n1 2 3\n", "off", "not an OFF file").line == 1
    err(f"OFF\n12 1 0\n{body}\n3 0 1 12\n".encode(), "off", "face 0 refers to vertex 12")
    e = err(f"OFF\n12 1 0\n{body}\n4 0 1 2\n".encode(), "off", "says 4 vertices")
    assert e.line == 15
    err(f"OFF\n12 2 0\n{body}\n3 0 1 2\n".encode(), "off", "header says 12 vertices and 2")
    err(b"OFF\ntwelve 1 0\n", "off", "expected the counts")
    err(b"4OFF\n", "off", "only 3D ascii OFF")


# --- robustness: damaged copies of valid files only ever raise FormatError ----------------

def _valid_files():
    rng = np.random.default_rng(11)
    pts = points(16)
    faces = [[0, 1, 2], [2, 3, 4, 5], [6, 7, 8], [9, 10, 11, 12, 13]]
    tri = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11], [12, 13, 14], [13, 14, 15]])
    cloud = PointCloud(points=pts, normals=pts / 3, faces=np.array(tri),
                       properties={"q": rng.normal(size=16).astype(np.float32)})
    obj = _obj(pts, "vn 0 0 1\nf 1//1 2//1 3//1\nf 4 5 6 7")
    stl = np.zeros(len(tri), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    stl["v"] = pts[tri]
    body = "\n".join(" ".join(map(str, p)) for p in pts.tolist())
    buf = io.BytesIO()
    np.save(buf, pts)
    return [
        ("ply", ascii_ply(pts, faces)),
        ("ply", binary_ply(pts, faces)),
        ("ply", binary_ply(pts, faces, order=">")),
        ("ply", write_bytes(cloud, "ply")),
        ("ply", write_bytes(cloud, "ply", binary=False)),
        ("csv", write_bytes(cloud, "csv")),
        ("npz", write_bytes(cloud, "npz")),
        ("npy", buf.getvalue()),
        ("pcd", pcd("ascii", pts)),
        ("pcd", pcd("binary", pts)),
        ("pcd", pcd("binary_compressed", pts)),
        ("obj", obj),
        ("stl", b"x" * 80 + struct.pack("<I", len(tri)) + stl.tobytes()),
        ("off", f"OFF\n16 2 0\n{body}\n3 0 1 2\n4 3 4 5 6\n".encode()),
        ("xyz", body.encode()),
    ]


def test_damaged_files_raise_only_format_errors():
    rng = np.random.default_rng(2024)
    tried = failed = 0
    for fmt, data in _valid_files():
        assert isinstance(read_bytes(data, fmt), PointCloud)  # the undamaged file is fine
        variants = [data[:int(c)] for c in rng.integers(1, len(data), 12)]
        for _ in range(25):
            damaged = bytearray(data)
            for pos in rng.integers(0, len(data), rng.integers(1, 4)):
                damaged[pos] = int(rng.integers(0, 256))
            variants.append(bytes(damaged))
        for variant in variants:
            tried += 1
            try:
                read_bytes(variant, fmt, source="damaged")
            except FormatError as exc:
                failed += 1
                assert str(exc).startswith("damaged")
    assert tried == 15 * 37 and failed > tried // 3


def test_point_count_and_finiteness_errors_have_their_own_types(tmp_path):
    import curvature

    few = tmp_path / "few.xyz"
    few.write_text("0 0 0\n1 0 0\n0 1 0\n")
    with pytest.raises(curvature.TooFewPointsError, match="at least 10"):
        curvature.read(few)
    bad = tmp_path / "nan.xyz"
    bad.write_text("".join(f"{i} 0 0\n" for i in range(12)) + "nan 1 1\n")
    with pytest.raises(curvature.NonFiniteError, match="NaN or Inf"):
        curvature.read(bad)
    assert issubclass(curvature.TooFewPointsError, curvature.FormatError)
    assert issubclass(curvature.NonFiniteError, ValueError)
