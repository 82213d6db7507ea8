"""Mesh ring neighborhoods (``mesh``, DESIGN.md section 4.3).

With faces, the 1-ring of p is the set of vertices sharing an edge with p. Without faces the
connectivity comes from the cloud: a local Delaunay triangulation in each point's tangent plane
(``k_delaunay`` nearest neighbors, PCA plane), made symmetric (see :mod:`.connectivity`). Rings
are then grown until at least ``min_neighbors`` vertices are gathered (see :mod:`.rings`). The
connectivity is built once per cloud, on the first query.
"""

from __future__ import annotations

import threading

import numpy as np

from ..params import ParamSpec
from ..validation import as_faces
from .base import NeighborFinder, Neighborhoods
from .candidates import TreeMixin, numba_threads
from .connectivity import cloud_graph, face_graph
from .rings import ring_neighborhoods


class MeshFinder(TreeMixin, NeighborFinder):
    """1-ring of a mesh (given, or a tangent-plane Delaunay mesh of the cloud), grown by rings.

    Neighbors of a query are listed ring by ring, in order of discovery.
    """

    name = "mesh"
    PARAMS = (
        ParamSpec("min_neighbors", int, 24, 1, 1000,
                  "rings are added until at least this many neighbors are gathered"),
        ParamSpec("k_delaunay", int, 16, 3, 256,
                  "without faces: nearest neighbors triangulated in each point's tangent plane"),
    )

    def __init__(self, points: np.ndarray, **kwargs):
        super().__init__(points, **kwargs)
        self.faces = as_faces(self.faces, points.shape[0])
        self._graph: tuple[np.ndarray, np.ndarray] | None = None
        self._lock = threading.Lock()

    def use_graph(self, graph: tuple[np.ndarray, np.ndarray]) -> None:
        """Use a vertex graph built elsewhere (a tile's part of the whole cloud's graph)."""
        with self._lock:
            self._graph = graph

    def graph(self, workers: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The vertex graph in CSR, built on first use.

        Parameters
        ----------
        workers : int
            Threads for building it (the graph does not depend on it).

        Returns
        -------
        indptr : ndarray, shape (n + 1,), int64
        indices : ndarray, shape (nnz,), int64
            Adjacent vertices of ``v``: ``indices[indptr[v]:indptr[v + 1]]``, increasing.
        """
        with self._lock:
            if self._graph is None:
                n = self.points.shape[0]
                if self.faces is not None:
                    self._graph = face_graph(self.faces, n)
                else:
                    with numba_threads(workers) as parallel:
                        self._graph = cloud_graph(self.nbpoints, self.nbtree,
                                                  self.params["k_delaunay"], parallel)
            return self._graph

    def query(self, idx: np.ndarray, workers: int = 1) -> Neighborhoods:
        """Ring neighborhoods of ``points[idx]``.

        Parameters
        ----------
        idx : ndarray, shape (m,), int64
            Query point indices.
        workers : int
            Threads to use; results do not depend on it.

        Returns
        -------
        Neighborhoods
            CSR, neighbors ring by ring.
        """
        indptr, indices = self.graph(workers)
        # without faces the k-d tree exists already and gives a cache-friendly order
        rank = self.nbtree[1] if self.faces is None else None
        with numba_threads(workers) as parallel:
            return ring_neighborhoods(indptr, indices, idx, self.params["min_neighbors"],
                                      parallel, rank)
