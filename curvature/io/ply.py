"""PLY (Stanford polygon file): read ascii / binary little / big endian, write ascii / binary.

Read: any vertex property order and type, normals ``nx ny nz``, faces from
``vertex_indices`` or ``vertex_index`` lists (fan-triangulated); other elements are skipped.
Write: ``x y z``, ``nx ny nz``, then result or extra fields, then faces as
``property list uchar int vertex_indices``; CloudCompare and MeshLab read these files and
show every extra property as a scalar field.
"""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError
from .checks import finish_cloud
from .columns import Table
from .faces import triangulate
from .ply_ascii import read_ascii_elements
from .ply_binary import read_binary_elements
from .ply_header import parse_header
from .tokens import number_texts

NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))
FACE_LISTS = ("vertex_indices", "vertex_index")
# Written under their own names (viewers know them); every other column gets SCALAR_PREFIX.
STANDARD_NAMES = frozenset({"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha",
                            "intensity", "quality"})
SCALAR_PREFIX = "scalar_"
_CHUNK_ROWS = 65536


def read_ply(data: bytes, source=None) -> PointCloud:
    """Decode a PLY file.

    Parameters
    ----------
    data : bytes
        The whole file.
    source : str, optional
        File name for messages.

    Returns
    -------
    PointCloud
        ``points`` (n, 3) float64 from ``x y z``; ``normals`` (n, 3) when ``nx ny nz`` (or
        ``normal_x ...``) exist; ``faces`` (m, 3) int64; other scalar vertex properties in
        ``properties`` with their declared type.

    Raises
    ------
    FormatError
        Any malformation, naming the line (ascii) or byte offset (binary).
    """
    header = parse_header(data, source)
    if header.element("vertex").count == 0:
        raise FormatError(source, "the file holds no points (element vertex 0)",
                          line=header.element("vertex").line)
    wanted = {"vertex", "face"}
    if header.format == "ascii":
        elements = read_ascii_elements(data, header, source, wanted)
    else:
        elements = read_binary_elements(data, header, source, wanted)
    vertex = elements["vertex"]
    cols = vertex.scalars
    points = np.stack([cols["x"], cols["y"], cols["z"]], axis=1, dtype=np.float64)
    used = {"x", "y", "z"}
    normals = None
    for names in NORMAL_NAMES:
        if all(n in cols for n in names):
            normals = np.stack([cols[n] for n in names], axis=1, dtype=np.float64)
            used.update(names)
            break
    properties = unprefixed({k: v for k, v in cols.items() if k not in used})
    cloud = finish_cloud(source, points, normals=normals, properties=properties,
                         where=vertex.where, label="vertex")
    cloud.viewpoint = header_viewpoint(header.comments, source)
    if cloud.viewpoint is not None:
        cloud.viewpoint_source = "PLY viewpoint comment"
    face = elements.get("face")
    if face is not None:
        name = next((n for n in FACE_LISTS if n in face.lists), None)
        if name is None and header.element("face").count:
            raise FormatError(source, "the face element has no 'vertex_indices' (or "
                                      "'vertex_index') list property",
                              line=header.element("face").line)
        if name is not None:
            counts, items = face.lists[name]
            if items.dtype.kind not in "iu":
                items = items.astype(np.int64)
            cloud.faces = triangulate(source, counts, items, len(cloud), where=face.where)
    return cloud


def header_viewpoint(comments: list[str], source) -> np.ndarray | None:
    """The scanner position of a ``comment viewpoint x y z`` (or ``obj_info viewpoint``)
    line, as (3,) float64; None when there is none.

    Raises
    ------
    FormatError
        The line does not hold three finite numbers.
    """
    for text in comments:
        tok = text.split()
        if not tok or tok[0].lower() != "viewpoint":
            continue
        try:
            vp = np.array([float(v) for v in tok[1:]], dtype=np.float64)
        except ValueError:
            vp = np.empty(0)
        if vp.size != 3 or not np.isfinite(vp).all():
            raise FormatError(source, "the header's viewpoint comment needs three finite "
                                      f"numbers 'viewpoint x y z', got {text[:80]!r}")
        return vp
    return None


def unprefixed(properties: dict) -> dict:
    """Properties with the ``scalar_`` prefix (ours, CloudCompare's) taken off the names,
    where that names no other property; our own ``quality`` copy of ``mean`` is dropped."""
    out = {}
    for name, values in properties.items():
        bare = name[len(SCALAR_PREFIX):] if name.startswith(SCALAR_PREFIX) else name
        out[bare if bare not in properties else name] = values
    if "quality" in out and "mean" in out and np.array_equal(
            out["quality"], np.asarray(out["mean"], dtype=np.float32), equal_nan=True):
        del out["quality"]
    return out


def _ply_column(arr: np.ndarray) -> tuple[str, np.ndarray]:
    """PLY type name and the array converted to it (PLY has no 64-bit integers)."""
    kind, size = arr.dtype.kind, arr.dtype.itemsize
    if kind == "b":
        return "uchar", arr.astype(np.uint8)
    if kind == "f":
        return ("float", arr.astype(np.float32)) if size <= 4 else ("double",
                                                                    arr.astype(np.float64))
    if kind == "i" and size <= 4:
        return {1: "char", 2: "short", 4: "int"}[size], arr
    if kind == "u" and size <= 4:
        return {1: "uchar", 2: "ushort", 4: "uint"}[size], arr
    info = np.iinfo(np.int32)
    if arr.size == 0 or (arr.min() >= info.min and arr.max() <= info.max):
        return "int", arr.astype(np.int32)
    return "double", arr.astype(np.float64)


def ply_name(name: str) -> str:
    """Property name a viewer recognises: standard names as they are, others ``scalar_*``.

    CloudCompare loads a vertex property as a named scalar field only when it is called
    ``scalar_<name>`` (or is a standard one: coordinates, normals, colours, intensity); it
    shows the field as ``<name>``. Measured with Debian's CloudCompare 2.11 (command line).
    """
    return name if name in STANDARD_NAMES or name.startswith(SCALAR_PREFIX) \
        else SCALAR_PREFIX + name


def write_ply(fh: BinaryIO, table: Table, *, binary: bool = True) -> None:
    """Write ``table`` as PLY (binary little endian, or ascii when ``binary=False``).

    Curvature and attribute columns are named ``scalar_<name>`` (see :func:`ply_name`) and
    mean curvature is repeated as ``quality``, the one per-vertex scalar MeshLab loads.
    """
    named = [(ply_name(name), arr) for name, arr in table.columns()]
    if "mean" in table.fields and "quality" not in table.fields:
        named.append(("quality", np.asarray(table.fields["mean"], dtype=np.float32)))
    columns = [(name, *_ply_column(np.asarray(arr))) for name, arr in named]
    faces = table.faces
    if faces is not None and faces.max(initial=0) > np.iinfo(np.int32).max:
        raise FormatError(None, "face indices do not fit PLY 'int'")
    fmt = "binary_little_endian" if binary else "ascii"
    head = ["ply", f"format {fmt} 1.0", "comment written by curvature"]
    for key, value in table.info.items():
        if isinstance(value, str | int | float | bool) and "\n" not in str(value):
            head.append(f"comment {key} {value}")
    vp = table.info.get("viewpoint")
    if isinstance(vp, list | tuple) and len(vp) == 3:
        head.append("comment viewpoint " + " ".join(repr(float(v)) for v in vp))
    head.append(f"element vertex {table.n}")
    head += [f"property {ptype} {name}" for name, ptype, _ in columns]
    if faces is not None:
        head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    head.append("end_header")
    fh.write(("\n".join(head) + "\n").encode("ascii"))
    if binary:
        _write_binary_body(fh, table.n, columns, faces)
    else:
        _write_ascii_body(fh, table.n, columns, faces)


def _write_binary_body(fh, n, columns, faces):
    dt = np.dtype([(f"p{i}", arr.dtype.newbyteorder("<")) for i, (_, _, arr)
                   in enumerate(columns)])
    for lo in range(0, n, _CHUNK_ROWS):
        hi = min(n, lo + _CHUNK_ROWS)
        rec = np.empty(hi - lo, dtype=dt)
        for i, (_, _, arr) in enumerate(columns):
            rec[f"p{i}"] = arr[lo:hi]
        fh.write(rec.tobytes())
    if faces is not None:
        rec = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        rec["n"] = 3
        rec["v"] = faces
        fh.write(rec.tobytes())


def _write_ascii_body(fh, n, columns, faces):
    for lo in range(0, n, _CHUNK_ROWS):
        hi = min(n, lo + _CHUNK_ROWS)
        texts = [number_texts(arr[lo:hi]) for _, _, arr in columns]
        fh.write(("\n".join(map(" ".join, zip(*texts, strict=True))) + "\n").encode("ascii"))
    if faces is not None:
        for lo in range(0, len(faces), _CHUNK_ROWS):
            part = faces[lo:lo + _CHUNK_ROWS].tolist()
            lines = [f"3 {a} {b} {c}" for a, b, c in part]
            fh.write(("\n".join(lines) + "\n").encode("ascii"))
