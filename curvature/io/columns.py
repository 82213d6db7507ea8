"""Column naming shared by readers and writers, and the table a writer works from.

A written file holds named per-point fields. Vectors are stored as three scalar columns whose
names follow the usual PLY conventions (``x y z``, ``nx ny nz``) so CloudCompare and MeshLab
recognise them; principal directions become ``d1x d1y d1z`` and ``d2x d2y d2z``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cloud import PointCloud
from ..errors import FormatError
from ..result import CurvatureResult
from .colors import expand_colors

VECTOR_COLUMNS = {
    "points": ("x", "y", "z"),
    "normals": ("nx", "ny", "nz"),
    "dir1": ("d1x", "d1y", "d1z"),
    "dir2": ("d2x", "d2y", "d2z"),
}
# Result fields in the order they are written (DESIGN.md section 6).
RESULT_ORDER = ("normals", "k1", "k2", "mean", "gaussian", "dir1", "dir2", "residual",
                "neighbor_count", "status", "k1_std", "k2_std", "mean_std", "uncertain")
# Result fields a file may lack (written by versions before them): NaN or derived when read.
OPTIONAL = ("k1_std", "k2_std", "mean_std", "uncertain")
# Written after them, computed from k1 and k2 (CurvatureResult.derived_fields).
DERIVED = ("shape_index", "curvedness")


def column_names(name: str, width: int) -> tuple[str, ...]:
    """Scalar column names for a field of ``width`` components (``"q"``, 2 -> ``q_0 q_1``)."""
    if width == 1:
        return (name,)
    if name in VECTOR_COLUMNS and width == 3:
        return VECTOR_COLUMNS[name]
    return tuple(f"{name}_{i}" for i in range(width))


@dataclass
class Table:
    """What a writer writes: ``n`` rows of named fields, optional triangles.

    Attributes
    ----------
    n : int
        Number of points.
    fields : dict of str to ndarray, shape (n,) or (n, k)
        ``"points"`` first, then the other fields in file order.
    faces : ndarray, shape (m, 3), int64, or None
    info : dict
        Result metadata (method, parameters) for formats that can carry it.
    """

    n: int
    fields: dict[str, np.ndarray]
    faces: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def columns(self) -> list[tuple[str, np.ndarray]]:
        """Scalar columns ``(name, array (n,))`` with vectors split into components."""
        out = []
        for name, arr in self.fields.items():
            if arr.ndim == 1:
                out.append((name, arr))
            else:
                for j, col in enumerate(column_names(name, arr.shape[1])):
                    out.append((col, arr[:, j]))
        return out


def table_of(obj, source=None) -> Table:
    """Build the :class:`Table` for a ``PointCloud``, ``CurvatureResult`` or (n, 3) array.

    Raises
    ------
    FormatError
        Unsupported object, wrong shapes, field lengths that differ from the point count,
        or a column name that appears twice.
    """
    if isinstance(obj, CurvatureResult):
        all_fields = obj.fields()
        order = [k for k in RESULT_ORDER if k in all_fields]
        order += [k for k in all_fields if k not in order]
        all_fields["status"] = np.asarray(all_fields["status"]).astype(np.uint8)  # 0..4
        all_fields["uncertain"] = np.asarray(all_fields["uncertain"]).astype(np.uint8)
        fields = {"points": obj.points, **{k: all_fields[k] for k in order},
                  **obj.derived_fields(), "index": obj.index}
        fields.update(expand_colors(dict(obj.attributes)))
        faces, info = obj.faces, dict(obj.info or {})
    elif isinstance(obj, PointCloud):
        fields = {"points": obj.points}
        if obj.normals is not None:
            fields["normals"] = obj.normals
        fields.update(expand_colors(dict(obj.properties)))
        faces, info = obj.faces, {}
    elif isinstance(obj, np.ndarray | list | tuple):
        fields, faces, info = {"points": obj}, None, {}
    else:
        raise FormatError(source, "can only write a PointCloud, a CurvatureResult or an "
                                  f"(n, 3) array, not {type(obj).__name__}")
    try:
        points = np.asarray(fields["points"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise FormatError(source, f"points are not numeric ({exc})") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise FormatError(source, f"points must have shape (n, 3), got {points.shape}")
    n = points.shape[0]
    checked = {"points": points}
    for name, values in fields.items():
        if name == "points":
            continue
        arr = np.asarray(values)
        if arr.dtype.kind not in "biuf":
            raise FormatError(source, f"field {name!r} is not numeric (dtype {arr.dtype})")
        if arr.ndim not in (1, 2) or arr.shape[0] != n:
            raise FormatError(source, f"field {name!r} has shape {arr.shape}, expected "
                                      f"({n},) or ({n}, k) to match the {n} points")
        checked[name] = arr
    table = Table(n=n, fields=checked, info=info)
    names = [c for c, _ in table.columns()]
    dupes = sorted({c for c in names if names.count(c) > 1})
    if dupes:
        raise FormatError(source, f"column name(s) {dupes} would appear twice")
    if faces is not None:
        faces = np.asarray(faces)
        if faces.size == 0:
            faces = None
        elif faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
            raise FormatError(source, f"faces must be integer (m, 3), got {faces.shape} "
                                      f"{faces.dtype}")
        elif faces.min() < 0 or faces.max() >= n:
            raise FormatError(source, f"faces refer to vertices outside 0..{n - 1}")
    table.faces = None if faces is None else faces.astype(np.int64, copy=False)
    return table


def split_vectors(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Flatten (n, k) arrays into scalar columns named by :func:`column_names`."""
    out = {}
    for name, arr in arrays.items():
        if arr.ndim == 1:
            out[name] = arr
        else:
            for j, col in enumerate(column_names(name, arr.shape[1])):
                out[col] = arr[:, j]
    return out


def result_from_cloud(cloud: PointCloud) -> CurvatureResult:
    """Rebuild a :class:`CurvatureResult` from a cloud read back from a result file.

    Raises
    ------
    FormatError
        A result field is missing from ``cloud.properties`` (or normals are missing).
    """
    props = cloud.properties

    def scalar(name):
        if name not in props:
            raise FormatError(cloud.source, f"not a curvature result: no {name!r} field")
        return props[name]

    def vector(name):
        cols = VECTOR_COLUMNS[name]
        return np.stack([np.asarray(scalar(c), dtype=np.float64) for c in cols], axis=1)

    if cloud.normals is None:
        raise FormatError(cloud.source, "not a curvature result: no normals")
    own = set(RESULT_ORDER) | set(DERIVED) | {c for name in VECTOR_COLUMNS
                                              for c in VECTOR_COLUMNS[name]}
    attributes = {k: v for k, v in props.items() if k not in own}
    optional = {name: np.asarray(props[name], dtype=np.uint8 if name == "uncertain"
                                 else np.float64) for name in OPTIONAL if name in props}
    return CurvatureResult(
        points=cloud.points,
        k1=np.asarray(scalar("k1"), dtype=np.float64),
        k2=np.asarray(scalar("k2"), dtype=np.float64),
        mean=np.asarray(scalar("mean"), dtype=np.float64),
        gaussian=np.asarray(scalar("gaussian"), dtype=np.float64),
        normals=cloud.normals,
        dir1=vector("dir1"),
        dir2=vector("dir2"),
        neighbor_count=np.asarray(scalar("neighbor_count")).astype(np.int32),
        status=np.asarray(scalar("status")).astype(np.int8),
        residual=np.asarray(scalar("residual"), dtype=np.float64),
        **optional,
        faces=cloud.faces,
        attributes=attributes,
    )
