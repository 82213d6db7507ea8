"""The structure every neighborhood method yields, and the finder interface.

A finder is prepared once per cloud (k-d tree, mesh connectivity) and then answers the
neighborhoods of any subset of points, so the pipeline can work through big clouds in chunks.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ParameterError
from ..params import ParamSpec, resolve_params


@dataclass
class Neighborhoods:
    """Ragged neighbor lists in CSR form; the query point itself is never listed.

    Attributes
    ----------
    indptr : ndarray, shape (m + 1,), int64
        Neighbors of query ``j`` are ``indices[indptr[j]:indptr[j + 1]]``.
    indices : ndarray, shape (nnz,), int32 or int64
        Indices into the cloud's points.
    """

    indptr: np.ndarray
    indices: np.ndarray

    def __len__(self) -> int:
        return int(self.indptr.shape[0] - 1)

    def __getitem__(self, j: int) -> np.ndarray:
        return self.indices[self.indptr[j]:self.indptr[j + 1]]

    def sizes(self) -> np.ndarray:
        """Number of neighbors per query point, shape (m,)."""
        return np.diff(self.indptr)

    @staticmethod
    def concatenate(parts: list[Neighborhoods]) -> Neighborhoods:
        """Join the neighborhoods of consecutive query chunks."""
        if not parts:
            return Neighborhoods(np.zeros(1, np.int64), np.zeros(0, np.int32))
        sizes = np.concatenate([p.sizes() for p in parts])
        indptr = np.zeros(sizes.size + 1, np.int64)
        np.cumsum(sizes, out=indptr[1:])
        return Neighborhoods(indptr, np.concatenate([p.indices for p in parts]))


class NeighborFinder(ABC):
    """Answers neighborhoods of query points of one cloud.

    Subclasses set ``name`` and ``PARAMS`` and implement :meth:`query`.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
        The cloud (already validated).
    tree : scipy.spatial.cKDTree, optional
        A tree over ``points`` to reuse.
    faces : ndarray, shape (m, 3), int64, optional
        Mesh faces, used by methods that need connectivity.
    **params
        Method parameters; validated against ``PARAMS``.
    """

    name: str = ""
    PARAMS: tuple[ParamSpec, ...] = ()

    def __init__(self, points: np.ndarray, *, tree: cKDTree | None = None,
                 faces: np.ndarray | None = None, **params):
        self.params = resolve_params(self.PARAMS, params, f"method '{self.name}'")
        self.validate(self.params)
        self.points = points
        self._tree = tree
        self.faces = faces

    @property
    def tree(self) -> cKDTree:
        """k-d tree over the cloud, built on first use."""
        if self._tree is None:
            self._tree = cKDTree(self.points, balanced_tree=False, compact_nodes=False)
        return self._tree

    def examined(self) -> int:
        """How many nearest points a query may examine beyond those it returns (0: none).

        Tiling adds the distance to that many nearest points to a point's reach.
        """
        return 0

    def validate(self, params: dict) -> None:  # noqa: B027 - optional hook
        """Check constraints between parameters; raise ParameterError on conflict."""

    def require_enough_candidates(self, params: dict) -> None:
        """Candidate-based methods cannot gather more neighbors than they examine."""
        if params["candidates"] < params["min_neighbors"]:
            raise ParameterError(
                f"method '{self.name}': candidates ({params['candidates']}) must be >= "
                f"min_neighbors ({params['min_neighbors']})")

    @abstractmethod
    def query(self, idx: np.ndarray, workers: int = 1) -> Neighborhoods:
        """Neighborhoods of ``points[idx]``, in the order of ``idx``.

        Parameters
        ----------
        idx : ndarray, shape (m,), int64
            Query point indices.
        workers : int
            Threads the finder may use.
        """
