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
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    faces: np.ndarray | None = None
    properties: dict[str, np.ndarray] = field(default_factory=dict)
    dropped: int = 0
    source: str | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])
