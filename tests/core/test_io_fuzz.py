"""Property-based fuzzing of every reader: corrupted files give FormatError, nothing else.

Each reader starts from a small valid file of its format; hypothesis truncates it, overwrites
bytes, splices in huge or negative numbers and repeats chunks. The only allowed outcomes are a
valid PointCloud or a FormatError, and memory stays bounded whatever a header claims.
"""

from __future__ import annotations

import io
import struct
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from curvature.cloud import PointCloud
from curvature.errors import FormatError
from curvature.io import read_bytes, write_bytes

POINTS = np.random.default_rng(0).random((12, 3))
TRIS = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6], [6, 7, 8], [8, 9, 10], [9, 10, 11]])
# Memory a reader may take on these tiny inputs, whatever their headers claim.
MEMORY_BOUND = 8_000_000


def _text_rows(fmt: str) -> bytes:
    return "".join(fmt.format(*p) for p in POINTS).encode()


def _pcd(data: str, body: bytes) -> bytes:
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
              f"WIDTH {len(POINTS)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(POINTS)}\n"
              f"DATA {data}\n")
    return header.encode() + body


def _pcd_compressed() -> bytes:
    raw = POINTS.astype("<f4").T.tobytes()  # PCD compresses column by column
    # Literal-only LZF runs (a control byte below 32 copies that many + 1 bytes).
    packed = b"".join(bytes([len(raw[i:i + 32]) - 1]) + raw[i:i + 32]
                      for i in range(0, len(raw), 32))
    return _pcd("binary_compressed", struct.pack("<II", len(packed), len(raw)) + packed)


def _ply_big_endian() -> bytes:
    head = (f"ply\nformat binary_big_endian 1.0\nelement vertex {len(POINTS)}\n"
            "property double x\nproperty double y\nproperty double z\n"
            f"element face {len(TRIS)}\nproperty list uchar int vertex_indices\nend_header\n")
    faces = b"".join(struct.pack(">B3i", 3, *t) for t in TRIS.tolist())
    return head.encode() + POINTS.astype(">f8").tobytes() + faces


def _stl_ascii() -> bytes:
    facets = "".join(
        "facet normal 0 0 1\n outer loop\n"
        + "".join("  vertex {} {} {}\n".format(*POINTS[v]) for v in tri)
        + " endloop\nendfacet\n" for tri in TRIS.tolist())
    return f"solid s\n{facets}endsolid s\n".encode()


def _npy() -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.hstack([POINTS, POINTS]))  # x y z nx ny nz
    return buffer.getvalue()


def _stl_binary() -> bytes:
    body = b"".join(struct.pack("<12fH", 0, 0, 1, *POINTS[a], *POINTS[b], *POINTS[c], 0)
                    for a, b, c in TRIS)
    return b"\0" * 80 + struct.pack("<I", len(TRIS)) + body


SEEDS = {
    "ply-binary": ("ply", write_bytes(PointCloud(points=POINTS, faces=TRIS), "ply")),
    "ply-ascii": ("ply", write_bytes(PointCloud(points=POINTS, faces=TRIS), "ply",
                                     binary=False)),
    "ply-big-endian": ("ply", _ply_big_endian()),
    "csv": ("csv", write_bytes(PointCloud(points=POINTS), "csv")),
    "xyz": ("xyz", _text_rows("{} {} {}\n")),
    "txt": ("txt", b"# x y z\n" + _text_rows("{}\t{}\t{}\n")),
    "npy": ("npy", _npy()),
    "npz": ("npz", write_bytes(PointCloud(points=POINTS), "npz")),
    "pcd-ascii": ("pcd", _pcd("ascii", _text_rows("{} {} {}\n"))),
    "pcd-binary": ("pcd", _pcd("binary", POINTS.astype("<f4").tobytes())),
    "pcd-compressed": ("pcd", _pcd_compressed()),
    "off": ("off", f"OFF\n{len(POINTS)} {len(TRIS)} 0\n".encode() + _text_rows("{} {} {}\n")
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in TRIS).encode()),
    "obj": ("obj", _text_rows("v {} {} {}\n")
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in TRIS).encode()),
    "stl-binary": ("stl", _stl_binary()),
    "stl-ascii": ("stl", _stl_ascii()),
}

SPLICES = [b"999999999999", b"-1", b"4294967295", b"nan", b"inf", b"\n", b" ", b"\0\0\0\0",
           b"\xff\xff\xff\xff", b"element vertex 99999999999\n", b"end_header\n", b"1e308"]


@st.composite
def corruptions(draw, data: bytes):
    """A corrupted copy of ``data``: truncation, overwrites, splices and repeats."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["truncate", "overwrite", "splice", "repeat", "delete"]))
        at = draw(st.integers(0, max(len(out) - 1, 0)))
        if kind == "truncate":
            del out[at:]
        elif kind == "overwrite":
            chunk = draw(st.binary(min_size=1, max_size=8))
            out[at:at + len(chunk)] = chunk
        elif kind == "splice":
            out[at:at] = draw(st.sampled_from(SPLICES))
        elif kind == "repeat":
            end = draw(st.integers(at, min(len(out), at + 64)))
            out[at:at] = out[at:end] * draw(st.integers(1, 20))
        else:
            end = draw(st.integers(at, min(len(out), at + 32)))
            del out[at:end]
    return bytes(out)


@pytest.mark.parametrize("name", list(SEEDS))
def test_seed_files_are_valid(name):
    fmt, data = SEEDS[name]
    assert len(read_bytes(data, fmt)) == len(POINTS)


@pytest.mark.parametrize("name", list(SEEDS))
def test_corrupted_files_raise_only_format_errors(name):
    fmt, seed = SEEDS[name]

    @settings(max_examples=60, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(corruptions(seed))
    def check(data):
        # A first read may load compiled kernels for a code path the seed did not take; the
        # bound is for the reader's own allocations, so measure a second read.
        try:
            read_bytes(data, fmt)
        except FormatError:
            pass
        tracemalloc.start()
        try:
            cloud = read_bytes(data, fmt)
        except FormatError:
            cloud = None
        finally:
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
        assert peak < MEMORY_BOUND, f"{peak} bytes for a {len(data)}-byte file"
        if cloud is not None:  # a corruption may still be a valid file; then it must be sane
            assert cloud.points.ndim == 2 and cloud.points.shape[1] == 3
            assert np.isfinite(cloud.points).all() and len(cloud) >= 10

    check()


def _nested(depth: int) -> bytes:
    return b"[" * depth + b"1" + b"]" * depth


def _npy_header(text: bytes) -> bytes:
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text) + 1) + text + b"\n"


def _first_vertex_replaced(data: bytes, row: bytes) -> bytes:
    head, body = data.split(b"end_header\n")
    return head + b"end_header\n" + row + b"\n" + body.split(b"\n", 1)[1]


# Inputs built to hurt: headers that lie about their counts by orders of magnitude, bodies
# cut inside a record, numbers beyond every range, and (in the NPY header, which numpy parses
# as a Python literal) nesting far beyond the parser's recursion limit.
ADVERSARIAL = {
    "ply-lying-count": ("ply", SEEDS["ply-binary"][1].replace(b"element vertex 12",
                                                               b"element vertex 4000000000")),
    "ply-lying-face-list": ("ply", SEEDS["ply-ascii"][1].replace(b"\n3 0 1 2",
                                                                 b"\n4294967295 0 1 2")),
    "ply-cut-in-a-record": ("ply", SEEDS["ply-binary"][1][:-7]),
    "ply-huge-ascii-numbers": ("ply", _first_vertex_replaced(
        SEEDS["ply-ascii"][1], b"9" * 5000 + b" 1e999999 -1e400")),
    "pcd-lying-points": ("pcd", SEEDS["pcd-binary"][1].replace(b"POINTS 12",
                                                               b"POINTS 999999999999")),
    "pcd-lying-compressed-size": ("pcd", SEEDS["pcd-compressed"][1].replace(
        b"DATA binary_compressed\n", b"DATA binary_compressed\n\xff\xff\xff\x7f\xff\xff\xff\x7f")),
    "stl-lying-count": ("stl", SEEDS["stl-binary"][1][:80] + struct.pack("<I", 2**32 - 1)
                        + SEEDS["stl-binary"][1][84:]),
    "off-lying-count": ("off", SEEDS["off"][1].replace(b"12 6 0", b"99999999999 6 0")),
    "xyz-huge-numbers": ("xyz", b"".join(b"%s 1 1\n" % (b"9" * 400) for _ in range(12))),
    "npy-deep-nesting": ("npy", _npy_header(b"{'descr': " + _nested(3000)
                                            + b", 'fortran_order': False, 'shape': (12, 3)}")),
    "npy-lying-shape": ("npy", SEEDS["npy"][1].replace(b"(12, 6)", b"(1200000000000, 6)")),
    "obj-deep-indices": ("obj", SEEDS["obj"][1] + b"f " + b"1/" * 20000 + b"1\n"),
}


@pytest.mark.parametrize("name", list(ADVERSARIAL))
def test_adversarial_inputs_raise_format_errors_in_bounded_memory(name):
    fmt, data = ADVERSARIAL[name]
    tracemalloc.start()
    try:
        with pytest.raises(FormatError):
            read_bytes(data, fmt)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < MEMORY_BOUND + 20 * len(data), f"{peak} bytes for a {len(data)}-byte file"
