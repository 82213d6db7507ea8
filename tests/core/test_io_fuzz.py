"""Property-based fuzzing of every reader: corrupted files give FormatError, nothing else.

Each reader starts from a small valid file of its format; hypothesis truncates it, overwrites
bytes, splices in huge or negative numbers and repeats chunks. The only allowed outcomes are a
valid PointCloud or a FormatError, and memory stays bounded whatever a header claims.
"""

from __future__ import annotations

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


def _stl_binary() -> bytes:
    body = b"".join(struct.pack("<12fH", 0, 0, 1, *POINTS[a], *POINTS[b], *POINTS[c], 0)
                    for a, b, c in TRIS)
    return b"\0" * 80 + struct.pack("<I", len(TRIS)) + body


SEEDS = {
    "ply-binary": ("ply", write_bytes(PointCloud(points=POINTS, faces=TRIS), "ply")),
    "ply-ascii": ("ply", write_bytes(PointCloud(points=POINTS, faces=TRIS), "ply",
                                     binary=False)),
    "csv": ("csv", write_bytes(PointCloud(points=POINTS), "csv")),
    "xyz": ("xyz", _text_rows("{} {} {}\n")),
    "npz": ("npz", write_bytes(PointCloud(points=POINTS), "npz")),
    "pcd-ascii": ("pcd", _pcd("ascii", _text_rows("{} {} {}\n"))),
    "pcd-binary": ("pcd", _pcd("binary", POINTS.astype("<f4").tobytes())),
    "off": ("off", f"OFF\n{len(POINTS)} {len(TRIS)} 0\n".encode() + _text_rows("{} {} {}\n")
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in TRIS).encode()),
    "obj": ("obj", _text_rows("v {} {} {}\n")
            + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in TRIS).encode()),
    "stl-binary": ("stl", _stl_binary()),
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
