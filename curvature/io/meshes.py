"""Mesh formats read for their vertices and triangles: OBJ, STL (ascii and binary), OFF."""

from __future__ import annotations

import itertools
import re

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError, NonFiniteError
from .checks import finish_cloud
from .faces import ragged_take, triangulate
from .tokens import decode_text, numbers, split_rows


def _integers(tokens: list[str], source, line_of, what: str) -> np.ndarray:
    """Tokens as int64; names the line of the first token that is not an integer."""
    try:
        return np.array(tokens, dtype=np.int64)
    except (ValueError, OverflowError):
        pass
    for i, tok in enumerate(tokens):
        try:
            int(tok)
        except ValueError:
            raise FormatError(source, f"{what} {tok[:40]!r} is not an integer",
                              line=line_of(i)) from None
    raise FormatError(source, f"a {what} is out of range")  # pragma: no cover - defensive


# --- OBJ -----------------------------------------------------------------------------------

def read_obj(data: bytes, source=None) -> PointCloud:
    """Decode a Wavefront OBJ: ``v``, ``vn`` and ``f`` lines (other statements ignored).

    Face corners may be ``v``, ``v/vt``, ``v/vt/vn`` or ``v//vn``; indices are 1-based, and
    negative ones count back from the last vertex defined before the face. Polygons are
    fan-triangulated. Normals are per vertex: taken from the ``vn`` each vertex is paired
    with in faces, or, without such pairings, ``vn`` in order when there is one per ``v``.
    """
    text = decode_text(data, source)
    v_rows, v_lines, n_rows, n_lines = [], [], [], []
    f_rows, f_lines, f_vbase, f_nbase = [], [], [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line or line[0] not in "vf":
            if not line or not line[0].isspace():
                continue  # fast skip of comments, vt, g, usemtl ...
            line = line.lstrip()
            if not line or line[0] not in "vf":
                continue
        parts = line.split()
        key = parts[0]
        if key == "v":
            v_rows.append(parts)
            v_lines.append(lineno)
        elif key == "vn":
            n_rows.append(parts)
            n_lines.append(lineno)
        elif key == "f":
            f_rows.append(parts)
            f_lines.append(lineno)
            f_vbase.append(len(v_rows))
            f_nbase.append(len(n_rows))
    points = _obj_vectors(v_rows, v_lines, source, "vertex 'v'")
    vn = _obj_vectors(n_rows, n_lines, source, "normal 'vn'") if n_rows else None
    n = points.shape[0]
    cloud = finish_cloud(source, points, where=lambda r: {"line": v_lines[int(r)]},
                         label="vertex")
    if not f_rows:
        if vn is not None and len(vn) == n:
            cloud.normals = vn
        return cloud
    counts = np.fromiter((len(p) - 1 for p in f_rows), dtype=np.int64, count=len(f_rows))
    corners = list(itertools.chain.from_iterable(p[1:] for p in f_rows))
    corner_face = np.repeat(np.arange(len(f_rows)), counts)

    def corner_line(i):
        return f_lines[int(corner_face[i])]

    if any("/" in c for c in corners):
        split = [c.split("/") for c in corners]
        v_tokens = [s[0] for s in split]
        n_tokens = [s[2] if len(s) > 2 else "" for s in split]
    else:
        v_tokens, n_tokens = corners, None
    v_idx = _obj_resolve(_integers(v_tokens, source, corner_line, "face vertex index"),
                         np.repeat(np.asarray(f_vbase, dtype=np.int64), counts),
                         source, corner_line, "vertex")
    cloud.faces = triangulate(source, counts, v_idx, n,
                              where=lambda r: {"line": f_lines[int(r)]})
    has_normal = (np.array([t != "" for t in n_tokens], dtype=bool)
                  if n_tokens is not None else np.zeros(len(corners), dtype=bool))
    if has_normal.any():
        picked = np.flatnonzero(has_normal)
        tokens = [n_tokens[i] for i in picked]
        n_idx = _obj_resolve(
            _integers(tokens, source, lambda i: corner_line(picked[i]), "face normal index"),
            np.repeat(np.asarray(f_nbase, dtype=np.int64), counts)[picked],
            source, lambda i: corner_line(picked[i]), "normal")
        n_count = 0 if vn is None else len(vn)
        bad = np.flatnonzero((n_idx < 0) | (n_idx >= n_count))
        if bad.size:
            raise FormatError(source, f"face refers to normal {int(n_idx[bad[0]]) + 1} but "
                                      f"only {n_count} 'vn' lines come before it",
                              line=corner_line(picked[bad[0]]))
        normals = np.full((n, 3), np.nan)
        normals[v_idx[picked]] = vn[n_idx]
        cloud.normals = normals
    elif vn is not None and len(vn) == n:
        cloud.normals = vn
    return cloud


def _obj_vectors(rows, lines, source, what) -> np.ndarray:
    lens = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
    short = np.flatnonzero(lens < 4)
    if short.size:
        raise FormatError(source, f"{what} line needs 3 numbers", line=lines[int(short[0])])
    return numbers([r[1:4] for r in rows], source, lambda r: lines[int(r)]).reshape(-1, 3)


def _obj_resolve(idx, base, source, line_of, what):
    """1-based and negative OBJ indices -> 0-based."""
    zero = np.flatnonzero(idx == 0)
    if zero.size:
        raise FormatError(source, f"{what} index 0 (OBJ indices start at 1)",
                          line=line_of(zero[0]))
    return np.where(idx < 0, base + idx, idx - 1)


# --- STL -----------------------------------------------------------------------------------

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_STL_PATTERN = np.array(["facet", "outer", "vertex", "vertex", "vertex", "endloop",
                         "endfacet"])


def read_stl(data: bytes, source=None) -> PointCloud:
    """Decode an STL file, ascii or binary (detected from the size and the ``solid`` word).

    Identical corner coordinates are merged so neighbouring triangles share vertices
    (first-appearance order). Facet normals are per triangle and therefore not kept.
    """
    n_binary = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    exact_binary = n_binary >= 0 and len(data) == 84 + 50 * n_binary
    if not exact_binary and data[:5].lower() == b"solid":
        corners, where = _stl_ascii(data, source)
    else:
        corners, where = _stl_binary(data, n_binary, source)
    finite = np.isfinite(corners).all(axis=1)
    if not finite.all():
        corner = int(np.flatnonzero(~finite)[0])
        raise NonFiniteError(source, f"triangle {corner // 3} has a NaN or Inf coordinate",
                          **where(corner))
    if corners.shape[0] == 0:
        raise FormatError(source, "the file holds no triangles")
    points, _, inverse = merge_identical(corners)
    cloud = finish_cloud(source, points, label="vertex")
    cloud.faces = inverse.reshape(-1, 3)
    return cloud


def _stl_binary(data, n, source):
    if n < 0:
        raise FormatError(source, f"too short for a binary STL ({len(data)} bytes, the header "
                                  "alone is 84)", offset=len(data))
    need = 84 + 50 * n
    if len(data) < need:
        raise FormatError(source, f"header says {n} triangles ({need} bytes) but the file has "
                                  f"{len(data)} bytes", offset=len(data))
    rec = np.frombuffer(data, dtype=_STL_RECORD, count=n, offset=84)
    corners = rec["v"].reshape(-1, 3).astype(np.float64)
    return corners, lambda c: {"offset": 84 + 50 * (c // 3) + 12 + 12 * (c % 3)}


def _stl_ascii(data, source):
    text = decode_text(data, source)
    numbered = [(i, ln) for i, ln in enumerate(text.splitlines(), start=1) if ln.strip()]
    rows, _ = split_rows([ln for _, ln in numbered])
    keep = [k for k, r in enumerate(rows) if r[0].lower() not in ("solid", "endsolid")]
    keywords = np.array([rows[k][0].lower() for k in keep], dtype=str)
    m = len(keep) // 7
    expected = np.resize(_STL_PATTERN, len(keep))
    wrong = np.flatnonzero(keywords != expected)
    if wrong.size or len(keep) % 7:
        at = int(wrong[0]) if wrong.size else len(keep)
        if at < len(keep):
            raise FormatError(source, f"expected '{expected[at]}' in ascii STL, found "
                                      f"{rows[keep[at]][0][:40]!r}", line=numbered[keep[at]][0])
        raise FormatError(source, "ascii STL ends inside a facet",
                          line=numbered[-1][0] if numbered else 1)
    vertex_rows = [keep[7 * f + j] for f in range(m) for j in (2, 3, 4)]
    lines = [numbered[k][0] for k in vertex_rows]
    bad = [i for i, k in enumerate(vertex_rows) if len(rows[k]) != 4]
    if bad:
        raise FormatError(source, "a 'vertex' line needs 3 numbers", line=lines[bad[0]])
    corners = numbers([rows[k][1:] for k in vertex_rows], source,
                      lambda i: lines[int(i)]).reshape(-1, 3)
    return corners, lambda c: {"line": lines[int(c)]}


def merge_identical(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge vertices with identical coordinates, keeping first-appearance order.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64

    Returns
    -------
    unique : ndarray, shape (u, 3)
    first : ndarray, shape (u,), int64
        Row of ``points`` where each unique vertex first appears.
    inverse : ndarray, shape (n,), int64
        Unique vertex of every input row.
    """
    pts = np.ascontiguousarray(points + 0.0)  # + 0.0 turns -0.0 into 0.0: same vertex
    keys = pts.view(np.dtype((np.void, pts.dtype.itemsize * 3))).reshape(-1)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return (pts[first[order]], first[order].astype(np.int64),
            rank[inverse.reshape(-1)].astype(np.int64))


# --- OFF -----------------------------------------------------------------------------------

_OFF_KEY = re.compile(r"(ST)?(C)?(N)?(4)?(n)?OFF")


def read_off(data: bytes, source=None) -> PointCloud:
    """Decode an ascii OFF (also NOFF / COFF / CNOFF / STOFF): vertices, then polygons.

    Vertex lines start with ``x y z`` (then normals for N variants; colours and texture
    coordinates are ignored); face lines are ``k i1 ... ik`` (a trailing colour is
    ignored). ``#`` starts a comment.
    """
    text = decode_text(data, source)
    numbered = []
    for i, ln in enumerate(text.splitlines(), start=1):
        ln = ln.split("#", 1)[0]
        if ln.strip():
            numbered.append((i, ln))
    if not numbered:
        raise FormatError(source, "the file holds no points")
    head = numbered[0][1].split()
    match = _OFF_KEY.fullmatch(head[0])
    if match is None:
        raise FormatError(source, "not an OFF file: the first line must be 'OFF' (or NOFF, "
                                  "COFF ...)", line=numbered[0][0])
    if match.group(4) or match.group(5) or "BINARY" in head[1:2]:
        raise FormatError(source, f"{head[0]} {' '.join(head[1:2])}: only 3D ascii OFF is "
                                  "read", line=numbered[0][0])
    with_normals = bool(match.group(3))
    if len(head) > 1:
        count_tokens, count_line, body = head[1:], numbered[0][0], numbered[1:]
    else:
        if len(numbered) < 2:
            raise FormatError(source, "no vertex and face counts after the OFF keyword")
        count_tokens, count_line, body = numbered[1][1].split(), numbered[1][0], numbered[2:]
    try:
        nv, nf = (int(t) for t in count_tokens[:2])
    except ValueError:
        raise FormatError(source, "expected the counts 'vertices faces edges'",
                          line=count_line) from None
    if nv < 0 or nf < 0:
        raise FormatError(source, "negative vertex or face count", line=count_line)
    if nv + nf > len(body):
        raise FormatError(source, f"header says {nv} vertices and {nf} faces but only "
                                  f"{len(body)} lines follow", line=count_line)
    v_lines = [i for i, _ in body[:nv]]
    rows, lens = split_rows([ln for _, ln in body[:nv]])
    need = 6 if with_normals else 3
    short = np.flatnonzero(lens < need)
    if short.size:
        raise FormatError(source, f"vertex line has {lens[short[0]]} values, expected at "
                                  f"least {need}", line=v_lines[int(short[0])])
    values = numbers([r[:need] for r in rows], source,
                     lambda r: v_lines[int(r)]).reshape(nv, need)
    cloud = finish_cloud(source, values[:, :3],
                         normals=values[:, 3:6] if with_normals else None,
                         where=lambda r: {"line": v_lines[int(r)]}, label="vertex")
    if nf == 0:
        return cloud
    f_lines = [i for i, _ in body[nv:nv + nf]]
    rows, lens = split_rows([ln for _, ln in body[nv:nv + nf]])
    counts = _integers([r[0] for r in rows], source, lambda r: f_lines[int(r)],
                       "face vertex count")
    bad = np.flatnonzero((counts < 0) | (counts + 1 > lens))
    if bad.size:
        r = int(bad[0])
        raise FormatError(source, f"face says {counts[r]} vertices but the line has "
                                  f"{lens[r] - 1} values", line=f_lines[r])
    flat = list(itertools.chain.from_iterable(rows))
    starts = np.cumsum(lens) - lens + 1
    picked = ragged_take(starts, counts)
    face_of = np.repeat(np.arange(nf), counts)
    indices = _integers([flat[i] for i in picked], source,
                        lambda i: f_lines[int(face_of[i])], "face vertex index")
    cloud.faces = triangulate(source, counts, indices, nv,
                              where=lambda r: {"line": f_lines[int(r)]})
    return cloud
