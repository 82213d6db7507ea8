"""Shared helpers of the candidate-based finders (``tc``, ``egg``) and the mesh finder.

Candidate lists come from :mod:`.kdtree` inside the numba kernels: the k nearest points sorted
by squared distance, ties broken by the point index, so the order a finder works in is fully
defined by the coordinates.
"""

from __future__ import annotations

from contextlib import contextmanager

import numba
import numpy as np

from .base import Neighborhoods
from .kdtree import build_tree

# Output entries (query x neighbor slot) handled at once; bounds memory on big clouds.
CHUNK_ENTRIES = 4_000_000
# Query points per numba block; scratch arrays are allocated once per block.
BLOCK = 256


def index_dtype(n: int) -> type:
    """Integer type of neighbor indices for a cloud of ``n`` points."""
    return np.int32 if n <= np.iinfo(np.int32).max else np.int64


@contextmanager
def numba_threads(workers: int):
    """Limit numba's parallel kernels to ``workers`` threads inside the block.

    Yields
    ------
    bool
        True when a parallel kernel should be used (more than one thread granted).
    """
    workers = max(1, int(workers or 1))
    granted = min(workers, numba.config.NUMBA_NUM_THREADS)
    if granted <= 1:
        yield False
        return
    previous = numba.get_num_threads()
    numba.set_num_threads(granted)
    try:
        yield True
    finally:
        numba.set_num_threads(previous)


def to_csr(out: np.ndarray, counts: np.ndarray, n: int) -> Neighborhoods:
    """Pack padded rows into CSR.

    Parameters
    ----------
    out : ndarray, shape (m, w), int64
        Row ``j`` holds its neighbors in ``out[j, :counts[j]]``.
    counts : ndarray, shape (m,), int64
    n : int
        Number of points in the cloud (chooses the index dtype).
    """
    m = counts.shape[0]
    indptr = np.zeros(m + 1, np.int64)
    np.cumsum(counts, out=indptr[1:])
    keep = np.arange(out.shape[1])[None, :] < counts[:, None]
    return Neighborhoods(indptr, out[keep].astype(index_dtype(n)))


def split_blocks(m: int) -> int:
    """Number of :data:`BLOCK`-sized blocks covering ``m`` queries."""
    return (m + BLOCK - 1) // BLOCK


class TreeMixin:
    """Adds :attr:`nbpoints` and :attr:`nbtree` (numba k-d tree), both made on first use."""

    _nbtree: tuple | None = None
    _nbpoints: np.ndarray | None = None

    @property
    def nbpoints(self) -> np.ndarray:
        """The cloud as a C-contiguous float64 array, shape (n, 3), for the numba kernels."""
        if self._nbpoints is None:
            self._nbpoints = np.ascontiguousarray(self.points, dtype=np.float64)
        return self._nbpoints

    @property
    def nbtree(self) -> tuple:
        """The tree of :func:`.kdtree.build_tree` over the cloud."""
        if self._nbtree is None:
            self._nbtree = build_tree(self.nbpoints)
        return self._nbtree
