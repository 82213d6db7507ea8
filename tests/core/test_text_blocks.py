"""Text readers walk their bodies in blocks: the result and every error's line must not
depend on where the blocks are cut (tiny blocks here put a cut in every few lines)."""

from __future__ import annotations

import numpy as np
import pytest

from curvature.errors import FormatError
from curvature.io import read_bytes, text_blocks


def _rows(pts: np.ndarray) -> list[str]:
    return [" ".join(f"{v:.6f}" for v in p) for p in pts]


def _files(n: int = 40) -> dict[str, tuple[str, bytes]]:
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(n, 3))
    rows = _rows(pts)
    tris = [(i, i + 1, i + 2) for i in range(n - 2)]
    quads = [(i, i + 1, i + 2, i + 3) for i in range(0, n - 3, 3)]
    xyz = "# a comment\n\n" + "\n".join(r if i % 7 else f"  {r}\n# inside\n" for i, r in
                                        enumerate(rows)) + "\n"
    csv = "x;y;z;t\n" + "\n".join(r.replace(".", ",").replace(" ", ";") + f";{i}"
                                  for i, r in enumerate(rows))
    pcd = ("VERSION .7\nFIELDS x y z _ _\nSIZE 4 4 4 4 4\nTYPE F F F F F\nCOUNT 1 1 1 2 1\n"
           f"WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA ascii\n"
           + "\n".join(f"{r} 9 9 9" if i % 5 else f"\n{r} 9 9 9" for i, r in enumerate(rows))
           + "\nextra lines are ignored\n")
    off = (f"OFF # counts next\n{n} {len(tris) + len(quads)} 0\n"
           + "\n".join(f"{r} # v{i}" for i, r in enumerate(rows)) + "\n"
           + "\n".join(f"3 {a} {b} {c}" for a, b, c in tris) + "\n"
           + "\n".join(f"4 {a} {b} {c} {d} 0.5 0.5 0.5" for a, b, c, d in quads) + "\n")
    obj = ("# obj\n" + "".join(f"v {r}\nvn 0 0 1\n" for r in rows)
           + "".join(f"f {a + 1}//{a + 1} {b + 1}/7/{b + 1} -1/3/-1\n" for a, b, _ in tris)
           + "g group\nusemtl m\n" + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in tris))
    ply = ("ply\nformat ascii 1.0\ncomment blocks\nelement skipped 5\nproperty float w\n"
           f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
           f"element face {len(quads)}\nproperty list uchar int vertex_indices\nend_header\n"
           + "1\n2\n3\n4\n5\n" + "\n".join(rows) + "\n"
           + "\n".join(f"4 {a} {b} {c} {d}" for a, b, c, d in quads) + "\n")
    return {"xyz": ("xyz", xyz.encode()), "csv": ("csv", csv.encode()),
            "pcd": ("pcd", pcd.encode()), "off": ("off", off.encode()),
            "obj": ("obj", obj.encode()), "ply": ("ply", ply.encode())}


@pytest.mark.parametrize("name", ["xyz", "csv", "pcd", "off", "obj", "ply"])
@pytest.mark.parametrize("block", [1, 17, 64, 300])
def test_result_does_not_depend_on_the_block_size(name, block, monkeypatch):
    fmt, data = _files()[name]
    whole = read_bytes(data, fmt, source=f"f.{fmt}")
    monkeypatch.setattr(text_blocks, "BLOCK_BYTES", block)
    cut = read_bytes(data, fmt, source=f"f.{fmt}")
    np.testing.assert_array_equal(cut.points, whole.points)
    assert len(whole.points) == 40
    for attr in ("normals", "faces"):
        a, b = getattr(whole, attr), getattr(cut, attr)
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(a, b)
    assert whole.properties.keys() == cut.properties.keys()
    for key in whole.properties:
        np.testing.assert_array_equal(whole.properties[key], cut.properties[key])
    if name in ("off", "ply", "obj"):
        assert whole.faces is not None and len(whole.faces) > 10
    if name == "csv":
        np.testing.assert_array_equal(whole.properties["t"], np.arange(40))


def _with_line(data: bytes, line: int, text: str) -> bytes:
    lines = data.split(b"\n")
    lines[line - 1] = text.encode()
    return b"\n".join(lines)


@pytest.mark.parametrize("name, line, text, match", [
    ("xyz", 30, "1 2 abc", "'abc' is not a number"),
    ("xyz", 31, "1 2", "2 columns, expected 3"),
    ("xyz", 32, "1 nan 3", "NaN or Inf"),
    ("pcd", 40, "1 2 x 9 9 9", "'x' is not a number"),
    ("off", 30, "1 2", "vertex line has 2 values"),
    ("off", 60, "3 0 1 99", "refers to vertex 99"),
    ("off", 61, "3 0 1.5 2", "not an integer"),
    ("obj", 41, "v 1 2 x", "'x' is not a number"),
    ("obj", 90, "f 1 2 x/1", "'x' is not an integer"),
    ("ply", 33, "1 2 3 4", "4 values, expected 3"),
])
@pytest.mark.parametrize("block", [16, 1 << 20])
def test_errors_name_the_same_line_whatever_the_block_size(name, line, text, match, block,
                                                           monkeypatch):
    fmt, data = _files()[name]
    monkeypatch.setattr(text_blocks, "BLOCK_BYTES", block)
    with pytest.raises(FormatError, match=match) as info:
        read_bytes(_with_line(data, line, text), fmt, source=f"f.{fmt}")
    assert info.value.line == line


def test_a_line_longer_than_the_limit_is_refused(monkeypatch):
    monkeypatch.setattr(text_blocks, "MAX_LINE_BYTES", 1000)
    monkeypatch.setattr(text_blocks, "BLOCK_BYTES", 256)
    data = b"1 2 3\n" * 20 + b"1 " * 600 + b"\n" + b"1 2 3\n" * 5
    with pytest.raises(FormatError, match="line longer than 1000 bytes") as info:
        read_bytes(data, "xyz", source="long.xyz")
    assert info.value.line == 21


def test_tokenize_finds_lines_and_tokens():
    tok = text_blocks.tokenize(b"  a bb\n\nccc\t d \r\ne")
    assert tok.line_ends.tolist() == [6, 7, 16, 18]
    assert tok.lens.tolist() == [2, 0, 2, 1]
    assert tok.starts.tolist() == [2, 4, 8, 13, 17]
    assert tok.ends.tolist() == [3, 6, 11, 14, 18]
    assert tok.line.tolist() == [0, 0, 2, 2, 3]
