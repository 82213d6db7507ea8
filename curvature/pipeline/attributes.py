"""What a result keeps of its input: per-point attributes, the input index, the viewpoint.

A :class:`~curvature.cloud.PointCloud` read from a file carries colours, intensity and any
other per-point field, each point's position in the file (``index``; the grid cell of an
organized scan) and, for single-view scans, where the scanner was. :func:`carry_input` puts
all of it on the result so every writer can hand it back, and :func:`file_viewpoint` says
which viewpoint, if any, orients the normals when the caller gave no orientation.
"""

from __future__ import annotations

import numpy as np

from ..cloud import PointCloud
from ..result import CurvatureResult

# Names a result's own fields (and their file columns) use; an input attribute with one of
# these names is kept under ``input_<name>`` so neither hides the other.
RESERVED = frozenset({
    "x", "y", "z", "nx", "ny", "nz", "k1", "k2", "mean", "gaussian", "residual",
    "neighbor_count", "status", "shape_index", "curvedness", "index", "row", "col",
    "d1x", "d1y", "d1z", "d2x", "d2y", "d2z",
})


def input_attributes(cloud: PointCloud) -> dict[str, np.ndarray]:
    """Per-point arrays a result carries from ``cloud``: ``index`` (, ``row``, ``col``), then
    every property of the cloud (renamed ``input_<name>`` where it clashes with a result
    field).

    Returns
    -------
    dict of str to ndarray, shape (n,)
    """
    index = cloud.input_index()
    out = {"index": index}
    if cloud.grid is not None:
        width = int(cloud.grid[0])
        out["row"] = (index // width).astype(np.int32)
        out["col"] = (index % width).astype(np.int32)
    for name, values in cloud.properties.items():
        out[f"input_{name}" if name in RESERVED else name] = np.asarray(values)
    return out


def file_viewpoint(cloud: PointCloud, orientation, normals, viewpoint):
    """The viewpoint recorded in the file, when it should orient the normals.

    It is used when the caller chose neither an orientation nor a viewpoint and the file has
    no normals (given normals are the stronger evidence), or asked for
    ``orientation="viewpoint"`` without giving one.

    Returns
    -------
    ndarray, shape (3,) or (n, 3), or None
    """
    if cloud.viewpoint is None or viewpoint is not None:
        return None
    if orientation == "viewpoint" or (orientation is None and normals is None):
        return np.asarray(cloud.viewpoint, dtype=np.float64)
    return None


def orientation_rule(mode: str, *, from_file: str | None, normals_from_file: bool) -> str:
    """A readable account of how normal signs were fixed, for ``result.info``."""
    if mode == "viewpoint":
        return f"viewpoint from the file ({from_file})" if from_file else "viewpoint given"
    if mode == "normals":
        return "normals from the file" if normals_from_file else "normals given"
    return "auto: consistent propagation, outward on balance"


def carry_input(result: CurvatureResult, cloud: PointCloud) -> CurvatureResult:
    """Attach ``cloud``'s attributes, index and grid to ``result`` (in place; returned)."""
    result.attributes = {**input_attributes(cloud), **result.attributes}
    if cloud.grid is not None:
        result.info["grid"] = {"width": int(cloud.grid[0]), "height": int(cloud.grid[1])}
    if cloud.dropped:
        result.info["dropped_points"] = int(cloud.dropped)
    return result
