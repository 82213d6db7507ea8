"""Polygon lists -> checked triangles, vectorized (no per-face Python loop)."""

from __future__ import annotations

import numpy as np

from ..errors import FormatError
from .checks import Locator, no_location


def ragged_take(flat_start: np.ndarray, counts: np.ndarray, step: int = 1) -> np.ndarray:
    """Indices ``flat_start[i] + k * step`` for ``k < counts[i]``, rows concatenated.

    Parameters
    ----------
    flat_start : ndarray, shape (m,), int64
    counts : ndarray, shape (m,), int64, non-negative
    step : int
        Distance between items (the item size when indexing bytes).

    Returns
    -------
    ndarray, shape (counts.sum(),), int64
    """
    counts = counts.astype(np.int64, copy=False)
    total = int(counts.sum())
    first = np.cumsum(counts) - counts
    within = np.arange(total, dtype=np.int64) - np.repeat(first, counts)
    return np.repeat(flat_start.astype(np.int64, copy=False), counts) + within * step


def triangulate(source, counts, indices, n_vertices: int, *,
                where: Locator = no_location, label: str = "face",
                first_row: int = 0) -> np.ndarray | None:
    """Fan-triangulate polygons and check that every index names an existing vertex.

    Parameters
    ----------
    source : str or None
        File name for messages.
    counts : ndarray, shape (m,), integer
        Vertices per polygon.
    indices : ndarray, shape (counts.sum(),), integer
        0-based vertex indices of all polygons, concatenated.
    n_vertices : int
        Number of vertices the indices may refer to.
    where : callable
        Maps a polygon row to ``line=``/``offset=`` for the error.
    first_row : int
        Number of the first polygon in messages (when polygons come in blocks).

    Returns
    -------
    ndarray, shape (t, 3), int64, or None
        Triangles ``(v0, vi, vi+1)`` per polygon; polygons with fewer than 3 vertices are
        skipped (lines and points carry no surface). ``None`` when nothing is left.

    Raises
    ------
    FormatError
        An index outside ``0 .. n_vertices - 1`` (names the polygon and the index).
    """
    counts = np.asarray(counts, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    if counts.size == 0:
        return None
    bad = (indices < 0) | (indices >= n_vertices)
    if bad.any():
        first_bad = int(np.flatnonzero(bad)[0])
        row = int(np.searchsorted(np.cumsum(counts), first_bad, side="right"))
        raise FormatError(
            source, f"{label} {first_row + row} refers to vertex {int(indices[first_bad])}, "
                    f"but there are only {n_vertices} vertices (valid 0..{n_vertices - 1})",
            **where(row))
    starts = np.cumsum(counts) - counts
    tris_per = np.maximum(counts - 2, 0)
    if tris_per.sum() == 0:
        return None
    if np.all(counts == 3):  # the common case: already triangles
        return indices.reshape(-1, 3).copy()
    poly = np.repeat(np.arange(counts.size), tris_per)
    k = np.arange(int(tris_per.sum())) - np.repeat(np.cumsum(tris_per) - tris_per, tris_per)
    base = starts[poly]
    return np.stack([indices[base], indices[base + k + 1], indices[base + k + 2]], axis=1)
