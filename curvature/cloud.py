"""In-memory point cloud as read from a file."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class PointCloud:
    """A point cloud with optional normals, faces and extra per-point properties.

    Attributes
    ----------
    points : ndarray, shape (n, 3), float64
        Coordinates.
    normals : ndarray, shape (n, 3), float64, or None
        Per-point normals when the file has them.
    faces : ndarray, shape (m, 3), int64, or None
        Triangles (polygons are fan-triangulated on read).
    properties : dict of str to ndarray, shape (n,)
        Other per-vertex properties (e.g. ``confidence``, ``intensity``, ``rgba``).
    dropped : int
        Rows dropped on read because a coordinate was NaN (organized PCD scans).
    source : str or None
        Where the cloud came from (file path), for messages.
    index : ndarray, shape (n,), int64, or None
        Each point's position in the input file (row of an organized grid counted row-major,
        NaN rows included); None means ``0 .. n-1``.
    grid : tuple of int (width, height), or None
        Size of an organized scan's grid; ``index = row * width + col``.
    viewpoint : ndarray, shape (3,) or (n, 3), float64, or None
        Scanner position the file records (PCD VIEWPOINT, E57 pose, PLY comment), for
        orienting a single-view scan; one row per point when the file holds several scans
        (each point's own scan origin, E57).
    viewpoint_source : str or None
        Where ``viewpoint`` came from, e.g. ``"PCD VIEWPOINT"``, for the result's info.
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    faces: np.ndarray | None = None
    properties: dict[str, np.ndarray] = field(default_factory=dict)
    dropped: int = 0
    source: str | None = None
    index: np.ndarray | None = None
    grid: tuple[int, int] | None = None
    viewpoint: np.ndarray | None = None
    viewpoint_source: str | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def input_index(self) -> np.ndarray:
        """Each point's position in the input file, shape (n,) int64."""
        if self.index is None:
            return np.arange(len(self), dtype=np.int64)
        return np.asarray(self.index, dtype=np.int64)
