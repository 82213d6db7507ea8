"""Mesh formats read for their vertices and triangles: OBJ, STL (ascii and binary), OFF."""

from __future__ import annotations

import re

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError, NonFiniteError, TooFewPointsError
from .checks import finish_cloud
from .faces import ragged_take, triangulate
from .text_blocks import RowScanner, blank_comments, gather, parse_floats, rows_values

# --- OBJ -----------------------------------------------------------------------------------

def read_obj(data: bytes, source=None) -> PointCloud:
    """Decode a Wavefront OBJ: ``v``, ``vn`` and ``f`` lines (other statements ignored).

    Face corners may be ``v``, ``v/vt``, ``v/vt/vn`` or ``v//vn``; indices are 1-based, and
    negative ones count back from the last vertex defined before the face. Polygons are
    fan-triangulated. Normals are per vertex: taken from the ``vn`` each vertex is paired
    with in faces, or, without such pairings, ``vn`` in order when there is one per ``v``.
    Read a block of lines at a time, each block's statements picked out with numpy.
    """
    scanner = RowScanner(data, 3 if data.startswith(b"\xef\xbb\xbf") else 0, 1, source)
    parts: dict[str, list] = {"v": [], "vn": [], "counts": [], "v_idx": [], "n_idx": [],
                              "face_line": []}
    n_v = n_n = 0
    for block in scanner.blocks():
        got = _obj_block(block, source, n_v, n_n)
        for key, value in got.items():
            parts[key].append(value)
        n_v += len(got["v"])
        n_n += len(got["vn"])
    if n_v == 0:
        raise TooFewPointsError(source, "the file holds no points")
    points = np.concatenate(parts["v"])
    vn = np.concatenate(parts["vn"]) if n_n else None
    cloud = finish_cloud(source, points, where=lambda r: {"line": _obj_v_line(scanner, r)},
                         label="vertex")
    counts = np.concatenate(parts["counts"])
    if counts.size == 0:
        if vn is not None and len(vn) == n_v:
            cloud.normals = vn
        return cloud
    v_idx = np.concatenate(parts["v_idx"])
    n_idx = np.concatenate(parts["n_idx"])
    face_line = np.concatenate(parts["face_line"])
    del parts
    cloud.faces = triangulate(source, counts, v_idx, n_v,
                              where=lambda r: {"line": int(face_line[int(r)])})
    has_normal = n_idx != _NO_NORMAL
    if has_normal.any():
        picked = np.flatnonzero(has_normal)
        bad = np.flatnonzero((n_idx[picked] < 0) | (n_idx[picked] >= n_n))
        if bad.size:
            corner = int(picked[bad[0]])
            face = int(np.searchsorted(np.cumsum(counts), corner, side="right"))
            raise FormatError(source, f"face refers to normal {int(n_idx[corner]) + 1} but "
                                      f"only {n_n} 'vn' lines come before it",
                              line=int(face_line[face]))
        normals = np.full((n_v, 3), np.nan)
        normals[v_idx[picked]] = vn[n_idx[picked]]
        cloud.normals = normals
    elif vn is not None and len(vn) == n_v:
        cloud.normals = vn
    return cloud


_NO_NORMAL = np.iinfo(np.int64).min  # a face corner without a normal index


def _obj_block(block, source, n_v: int, n_n: int) -> dict[str, np.ndarray]:
    """The ``v``, ``vn`` and ``f`` statements of one block, as arrays; face indices are
    resolved to 0-based with the counts of ``v`` (``n_v``) and ``vn`` (``n_n``) lines of the
    blocks before."""
    tok, raw = block.tokens, np.frombuffer(block.buf, dtype=np.uint8)
    lines = block.rows
    first = tok.first()[lines]
    key_at, key_len = tok.starts[first], tok.ends[first] - tok.starts[first]
    c0 = raw[key_at]
    c1 = raw[np.minimum(key_at + 1, raw.size - 1)]
    is_v = (key_len == 1) & (c0 == ord("v"))
    is_vn = (key_len == 2) & (c0 == ord("v")) & (c1 == ord("n"))
    is_f = (key_len == 1) & (c0 == ord("f"))
    out = {"v": _obj_vectors(block, lines[is_v], first[is_v], source, "vertex 'v'"),
           "vn": _obj_vectors(block, lines[is_vn], first[is_vn], source, "normal 'vn'")}
    f_lines, f_first = lines[is_f], first[is_f]
    counts = tok.lens[f_lines] - 1
    # Bases for negative indices: the vertices and normals defined before each face.
    before = np.cumsum(is_v)[is_f] - 1 + n_v + 1
    before_n = np.cumsum(is_vn)[is_f] - 1 + n_n + 1
    corner = ragged_take(f_first + 1, counts)
    corner_face = np.repeat(np.arange(counts.size), counts)
    cs, ce = tok.starts[corner], tok.ends[corner]
    slashes = np.flatnonzero(raw == ord("/"))
    owner = np.searchsorted(ce, slashes)  # the corner token holding each slash
    inside = owner < corner.size
    inside[inside] = cs[owner[inside]] <= slashes[inside]
    slashes, owner = slashes[inside], owner[inside]
    nth = np.arange(owner.size) - np.searchsorted(owner, owner)  # 0 for a corner's first '/'
    v_end = ce.copy()
    v_end[owner[nth == 0]] = slashes[nth == 0]
    n_start = ce.copy()
    n_start[owner[nth == 1]] = slashes[nth == 1] + 1
    file_line = block.first_line + f_lines

    def corner_line(i) -> int:
        return int(file_line[corner_face[int(i)]])

    v_idx = _obj_indices(block.buf, cs, v_end, source, corner_line, "face vertex index")
    has_n = n_start < ce
    n_idx = np.full(corner.size, _NO_NORMAL, dtype=np.int64)
    if has_n.any():
        picked = np.flatnonzero(has_n)
        n_idx[picked] = _obj_resolve(
            _obj_indices(block.buf, n_start[picked], ce[picked], source,
                         lambda i: corner_line(picked[int(i)]), "face normal index"),
            np.repeat(before_n, counts)[picked], source,
            lambda i: corner_line(picked[int(i)]), "normal")
    out["counts"] = counts
    out["v_idx"] = _obj_resolve(v_idx, np.repeat(before, counts), source, corner_line,
                                "vertex")
    out["n_idx"] = n_idx
    out["face_line"] = file_line
    return out


def _obj_indices(buf, lo, hi, source, line_of, what) -> np.ndarray:
    """The integers in the byte ranges ``[lo, hi)`` of ``buf`` (one each)."""
    empty = np.flatnonzero(hi <= lo)
    if empty.size:
        raise FormatError(source, f"{what} '' is not an integer", line=line_of(empty[0]))
    values = parse_floats(gather(buf, lo, hi), lo.size, source, line_of,
                          expected=f"an integer ({what})")
    frac = np.flatnonzero(values != np.floor(values))
    if frac.size:
        raise FormatError(source, f"{what} {values[frac[0]]:g} is not an integer",
                          line=line_of(frac[0]))
    return values.astype(np.int64)


def _obj_vectors(block, lines, first, source, what) -> np.ndarray:
    """Three numbers after the keyword of each of the given lines, shape (k, 3)."""
    tok = block.tokens
    short = np.flatnonzero(tok.lens[lines] < 4)
    if short.size:
        raise FormatError(source, f"{what} line needs 3 numbers",
                          line=block.first_line + int(lines[short[0]]))
    text = gather(block.buf, tok.starts[first + 1], tok.ends[first + 3])
    return parse_floats(text, 3 * lines.size, source,
                        lambda i: block.first_line + int(lines[i])).reshape(-1, 3)


def _obj_v_line(scanner, row: int) -> int:
    """File line of the ``row``-th ``v`` statement (for error messages)."""
    seen = 0
    for block in scanner.blocks():
        tok, raw = block.tokens, np.frombuffer(block.buf, dtype=np.uint8)
        first = tok.first()[block.rows]
        at = tok.starts[first]
        is_v = ((tok.ends[first] - at) == 1) & (raw[at] == ord("v"))
        v_lines = block.rows[is_v]
        if row < seen + v_lines.size:
            return block.first_line + int(v_lines[row - seen])
        seen += v_lines.size
    raise IndexError(row)  # pragma: no cover - callers pass rows that exist


def _obj_resolve(idx, base, source, line_of, what):
    """1-based and negative OBJ indices -> 0-based."""
    zero = np.flatnonzero(idx == 0)
    if zero.size:
        raise FormatError(source, f"{what} index 0 (OBJ indices start at 1)",
                          line=line_of(zero[0]))
    return np.where(idx < 0, base + idx, idx - 1)


# --- STL -----------------------------------------------------------------------------------

_STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])

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
    corners = rec["v"].reshape(-1, 3)  # float32 as stored: merged before widening
    return corners, lambda c: {"offset": 84 + 50 * (c // 3) + 12 + 12 * (c % 3)}


_STL_WORDS = ("facet", "outer", "vertex", "endloop", "endfacet", "solid", "endsolid")
_STL_CODES = np.array([0, 1, 2, 2, 2, 3, 4])  # facet outer vertex x3 endloop endfacet
_WORD_BYTES = 8


def _stl_ascii(data, source):
    """Corners of an ascii STL, a block of lines at a time; keywords compared with numpy."""
    scanner = RowScanner(data, 0, 1, source)
    words = np.zeros((len(_STL_WORDS), _WORD_BYTES), dtype=np.uint8)
    for i, w in enumerate(_STL_WORDS):
        words[i, :len(w)] = np.frombuffer(w.encode(), dtype=np.uint8)
    corners, phase = [], 0
    for block in scanner.blocks():
        tok, raw = block.tokens, np.frombuffer(block.buf, dtype=np.uint8)
        first = tok.first()[block.rows]
        code = _keyword_codes(raw, tok.starts[first], tok.ends[first], words)
        keep = code < 5  # solid / endsolid lines frame the facets
        lines, first, code = block.rows[keep], first[keep], code[keep]
        expected = _STL_CODES[(phase + np.arange(code.size)) % 7]
        wrong = np.flatnonzero(code != expected)
        if wrong.size:
            at = int(wrong[0])
            shown = bytes(raw[tok.starts[first[at]]:tok.ends[first[at]]][:40]).decode("latin-1")
            raise FormatError(source, f"expected '{_STL_WORDS[expected[at]]}' in ascii STL, "
                                      f"found {shown!r}", line=block.first_line + int(lines[at]))
        is_vertex = code == 2
        v_lines, v_first = lines[is_vertex], first[is_vertex]
        bad = np.flatnonzero(tok.lens[v_lines] != 4)
        if bad.size:
            raise FormatError(source, "a 'vertex' line needs 3 numbers",
                              line=block.first_line + int(v_lines[bad[0]]))
        text = gather(block.buf, tok.starts[v_first + 1], tok.ends[v_first + 3])
        corners.append(parse_floats(text, 3 * v_lines.size, source,
                                    lambda i, b=block, v=v_lines: b.first_line + int(v[i])
                                    ).reshape(-1, 3))
        phase = (phase + code.size) % 7
    if phase:
        raise FormatError(source, "ascii STL ends inside a facet", line=scanner.end_line)
    corners = np.concatenate(corners) if corners else np.zeros((0, 3))
    return corners, lambda c: {"line": _stl_corner_line(scanner, int(c), words)}


def _keyword_codes(raw, starts, ends, words) -> np.ndarray:
    """Index in ``_STL_WORDS`` of each token ``raw[starts:ends]`` (lower-cased), or
    ``len(_STL_WORDS)`` for any other word."""
    length = ends - starts
    k = np.arange(_WORD_BYTES)
    at = np.minimum(starts[:, None] + k, raw.size - 1)
    chars = np.where(k < length[:, None], raw[at], 0).astype(np.uint8)
    chars = np.where((chars >= 65) & (chars <= 90), chars + 32, chars).astype(np.uint8)
    match = (chars[:, None, :] == words[None, :, :]).all(axis=2) & (length <= _WORD_BYTES
                                                                     )[:, None]
    return np.where(match.any(axis=1), match.argmax(axis=1), len(_STL_WORDS))


def _stl_corner_line(scanner, corner: int, words) -> int:
    """File line of the ``corner``-th 'vertex' line (for error messages)."""
    seen = 0
    for block in scanner.blocks():
        tok, raw = block.tokens, np.frombuffer(block.buf, dtype=np.uint8)
        first = tok.first()[block.rows]
        v_lines = block.rows[_keyword_codes(raw, tok.starts[first], tok.ends[first],
                                            words) == 2]
        if corner < seen + v_lines.size:
            return block.first_line + int(v_lines[corner - seen])
        seen += v_lines.size
    raise IndexError(corner)  # pragma: no cover - callers pass corners that exist


def merge_identical(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Merge vertices with identical coordinates, keeping first-appearance order.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float32 or float64
        (Binary STL corners stay float32 until merged: identical in the file, identical here.)

    Returns
    -------
    unique : ndarray, shape (u, 3), float64
    first : ndarray, shape (u,), int64
        Row of ``points`` where each unique vertex first appears.
    inverse : ndarray, shape (n,), int64
        Unique vertex of every input row.
    """
    pts = np.ascontiguousarray(points + points.dtype.type(0))  # -0.0 -> 0.0: same vertex
    keys = pts.view(np.dtype((np.void, pts.dtype.itemsize * 3))).reshape(-1)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return (pts[first[order]].astype(np.float64), first[order].astype(np.int64),
            rank[inverse.reshape(-1)].astype(np.int64))


# --- OFF -----------------------------------------------------------------------------------

_OFF_KEY = re.compile(r"(ST)?(C)?(N)?(4)?(n)?OFF")


def read_off(data: bytes, source=None) -> PointCloud:
    """Decode an ascii OFF (also NOFF / COFF / CNOFF / STOFF): vertices, then polygons.

    Vertex lines start with ``x y z`` (then normals for N variants; colours and texture
    coordinates are ignored); face lines are ``k i1 ... ik`` (a trailing colour is
    ignored). ``#`` starts a comment. Read a block of lines at a time.
    """
    def prepare(buf: bytes) -> bytes:
        return blank_comments(buf, anywhere=True)

    head_scan = RowScanner(data, 0, 1, source, prepare)
    head = [(block.first_line + int(r), _line_text(block, int(r)).split())
            for block in head_scan.blocks(max_rows=2) for r in block.rows]
    if not head:
        raise FormatError(source, "the file holds no points")
    keyword_line, words = head[0]
    match = _OFF_KEY.fullmatch(words[0])
    if match is None:
        raise FormatError(source, "not an OFF file: the first line must be 'OFF' (or NOFF, "
                                  "COFF ...)", line=keyword_line)
    if match.group(4) or match.group(5) or "BINARY" in words[1:2]:
        raise FormatError(source, f"{words[0]} {' '.join(words[1:2])}: only 3D ascii OFF is "
                                  "read", line=keyword_line)
    with_normals = bool(match.group(3))
    if len(words) > 1:
        count_tokens, count_line = words[1:], keyword_line
    else:
        if len(head) < 2:
            raise FormatError(source, "no vertex and face counts after the OFF keyword")
        count_line, count_tokens = head[1]
    try:
        nv, nf = (int(t) for t in count_tokens[:2])
    except ValueError:
        raise FormatError(source, "expected the counts 'vertices faces edges'",
                          line=count_line) from None
    if nv < 0 or nf < 0:
        raise FormatError(source, "negative vertex or face count", line=count_line)
    for _ in head_scan.blocks(max_rows=1 if len(words) > 1 else 2):
        pass  # to where the body starts
    need = 6 if with_normals else 3
    vertices = RowScanner(data, head_scan.end, head_scan.end_line, source, prepare)
    # A vertex line takes >= 2 bytes a value and a face line >= 2 bytes: refuse counts the
    # bytes cannot hold before allocating for them.
    fits = nv * 2 * need + nf * 2 <= len(data) - head_scan.end + 1
    found = 0
    for block in vertices.blocks(nv if fits else 0):  # pass 1: every vertex line long enough
        lens = block.tokens.lens[block.rows]
        short = np.flatnonzero(lens < need)
        if short.size:
            raise FormatError(source, f"vertex line has {lens[short[0]]} values, expected at "
                                      f"least {need}",
                              line=block.first_line + int(block.rows[short[0]]))
        found += block.rows.size
    if not fits or found < nv:
        total = sum(b.rows.size for b in vertices.blocks())
        if not fits or total < nv + nf:
            raise FormatError(source, f"header says {nv} vertices and {nf} faces but only "
                                      f"{total} lines follow", line=count_line)
    values = np.empty((nv, need), dtype=np.float64)
    at = 0
    for block in vertices.blocks(nv):  # pass 2: the first `need` values of every line
        lens = block.tokens.lens[block.rows]
        first = np.cumsum(lens) - lens
        flat = rows_values(block, source)
        values[at:at + lens.size] = flat[first[:, None] + np.arange(need)]
        at += lens.size
    cloud = finish_cloud(source, values[:, :3],
                         normals=values[:, 3:6] if with_normals else None,
                         where=lambda r: {"line": vertices.line_of_row(int(r), nv)},
                         label="vertex")
    if nf == 0:
        return cloud
    faces = RowScanner(data, vertices.end, vertices.end_line, source, prepare)
    triangles, done = [], 0
    for block in faces.blocks(nf):
        tris = _off_faces(block, source, nv, done)
        if tris is not None:
            triangles.append(tris)
        done += block.rows.size
    if done < nf:
        raise FormatError(source, f"header says {nv} vertices and {nf} faces but only "
                                  f"{nv + done} lines follow", line=count_line)
    cloud.faces = np.concatenate(triangles) if triangles else None
    return cloud


def _line_text(block, row: int) -> str:
    """The text of one line of a block (prepared: comments blanked)."""
    lo = int(block.tokens.line_ends[row - 1]) + 1 if row else 0
    return block.buf[lo:int(block.tokens.line_ends[row])].decode("latin-1")


def _off_faces(block, source, n_vertices: int, first_face: int) -> np.ndarray | None:
    """Triangles of one block of OFF face lines ``k i1 ... ik [colour]``."""
    lens = block.tokens.lens[block.rows]
    flat = rows_values(block, source)
    starts = np.cumsum(lens) - lens

    def line(r) -> int:
        return block.first_line + int(block.rows[int(r)])

    counts = flat[starts]
    bad = np.flatnonzero((counts != np.floor(counts)) | (counts < 0) | (counts + 1 > lens))
    if bad.size:
        r = int(bad[0])
        if counts[r] != np.floor(counts[r]) or counts[r] < 0:
            raise FormatError(source, f"face vertex count {counts[r]:g} is not a "
                                      "non-negative integer", line=line(r))
        raise FormatError(source, f"face says {int(counts[r])} vertices but the line has "
                                  f"{lens[r] - 1} values", line=line(r))
    counts = counts.astype(np.int64)
    items = flat[ragged_take(starts + 1, counts)]
    frac = np.flatnonzero(items != np.floor(items))
    if frac.size:
        r = int(np.searchsorted(np.cumsum(counts), frac[0], side="right"))
        raise FormatError(source, f"face vertex index {items[frac[0]]:g} is not an integer",
                          line=line(r))
    out = np.flatnonzero((items < 0) | (items >= n_vertices))
    if out.size:
        r = int(np.searchsorted(np.cumsum(counts), out[0], side="right"))
        raise FormatError(source, f"face {first_face + r} refers to vertex {items[out[0]]:.0f}"
                                  f", but there are only {n_vertices} vertices (valid "
                                  f"0..{n_vertices - 1})", line=line(r))
    return triangulate(source, counts, items.astype(np.int64), n_vertices, first_row=first_face,
                       where=lambda r: {"line": line(r)})
