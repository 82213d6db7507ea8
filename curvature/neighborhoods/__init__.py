"""Neighborhood methods: knn, tc (Territory Claiming), egg (Elliptic Gabriel Graph), mesh.

All yield :class:`Neighborhoods` (CSR) so any method feeds any fit model.
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..validation import as_points
from .base import NeighborFinder, Neighborhoods
from .knn import KnnFinder

FINDERS: dict[str, type[NeighborFinder]] = {"knn": KnnFinder}

try:  # methods of issue 3, registered when present
    from .territory import TerritoryFinder

    FINDERS["tc"] = TerritoryFinder
except ImportError:  # pragma: no cover
    pass
try:
    from .egg import EggFinder

    FINDERS["egg"] = EggFinder
except ImportError:  # pragma: no cover
    pass
try:
    from .mesh import MeshFinder

    FINDERS["mesh"] = MeshFinder
except ImportError:  # pragma: no cover
    pass


def make_finder(points: np.ndarray, method: str = "knn", *, faces=None, tree=None,
                **params) -> NeighborFinder:
    """Prepare the finder of ``method`` for a validated cloud; parameters are checked here."""
    try:
        cls = FINDERS[method]
    except KeyError:
        raise ParameterError(
            f"unknown method {method!r}; choose one of {sorted(FINDERS)}") from None
    return cls(points, tree=tree, faces=faces, **params)


def neighbors(points, method: str = "knn", *, faces=None, workers: int = 1,
              **params) -> Neighborhoods:
    """Neighborhoods of every point of a cloud.

    Parameters
    ----------
    points : array_like, shape (n, 3)
        The cloud.
    method : {"knn", "tc", "egg", "mesh"}
        Neighborhood method (DESIGN.md section 4).
    faces : array_like, shape (m, 3), optional
        Mesh faces for ``method="mesh"``.
    workers : int
        Threads to use.
    **params
        Method parameters (see ``FINDERS[method].PARAMS``).

    Returns
    -------
    Neighborhoods
        CSR arrays ``indptr`` (n + 1,) and ``indices``; the query point itself not listed.
    """
    pts = as_points(points)
    finder = make_finder(pts, method, faces=faces, **params)
    return finder.query(np.arange(len(pts), dtype=np.int64), workers=workers)


__all__ = ["FINDERS", "NeighborFinder", "Neighborhoods", "make_finder", "neighbors"]
