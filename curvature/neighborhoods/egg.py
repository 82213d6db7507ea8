"""Elliptic Gabriel Graph neighborhoods (``egg``, DESIGN.md section 4.2).

For the edge (p, q) let ``m = (p + q) / 2``, ``d = |pq| / 2`` and ``e = (q - p) / |q - p|``.
Another point r blocks q iff ``u^2 + w^2 / alpha^2 < d^2`` with ``u = (r - m).e`` and
``w^2 = |r - m|^2 - u^2``: r lies inside the spheroid with semi-axis d along pq and alpha*d
across. q is a neighbor of p iff no candidate blocks it; only candidates nearer to p than q can
block (a blocker lies inside the sphere on pq as diameter), so testing the earlier entries of
the sorted candidate list is exact. alpha starts at ``alpha_start`` and is lowered by
``alpha_step`` until at least ``min_neighbors`` neighbors are found, down to
``alpha = alpha_step``, whose set is used when even it is too small.

One pass serves every alpha: the spheroid shrinks as alpha falls, so r blocks q for the
largest alphas of the schedule only, and q's first unblocked alpha is a maximum over r. All
computations are done in coordinates relative to p; ``w^2`` is clamped at 0 (it can come out a
few ulps negative when r lies on the line pq), which keeps the test monotone in alpha also in
floating point.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..errors import ParameterError
from ..params import ParamSpec
from .base import NeighborFinder, Neighborhoods
from .candidates import BLOCK, CHUNK_ENTRIES, TreeMixin, numba_threads, to_csr
from .kdtree import knn_point, knn_scratch, query_order

MAX_ALPHAS = 10_000


def alpha_values(alpha_start: float, alpha_step: float) -> np.ndarray:
    """The alpha schedule: ``round(alpha_start - i * alpha_step, 10)`` down to ``alpha_step``.

    Returns
    -------
    ndarray, shape (na,), float64
        Decreasing; empty when ``alpha_start < alpha_step``.
    """
    bottom = round(alpha_step, 10)
    out = []
    i = 0
    while len(out) <= MAX_ALPHAS:
        a = round(alpha_start - i * alpha_step, 10)
        if a < bottom or not a > 0.0:
            break
        out.append(a)
        i += 1
    return np.asarray(out, dtype=np.float64)


@njit(cache=True, inline="always")
def spheroid_blocks(u, w2, d2, alpha2):
    """True when r blocks q: ``u^2 + w^2 / alpha^2 < d^2``.

    Parameters
    ----------
    u : float
        ``(r - m) . e``.
    w2 : float
        ``|r - m|^2 - u^2`` (clamped at 0).
    d2 : float
        ``d^2``, the squared half length of pq.
    alpha2 : float
        ``alpha * alpha``.
    """
    return u * u + w2 / alpha2 < d2


@njit(cache=True)
def _egg_range(points, tree, idx, order, lo, hi, k, alpha2, min_nb, out, counts):
    """EGG neighbors for the queries ``idx[order[lo:hi]]``.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    tree : tuple
        :func:`.kdtree.build_tree` over ``points``.
    idx : ndarray, shape (m,), int64
        Query points.
    order : ndarray, shape (m,), int64
        Processing order (any permutation; results do not depend on it).
    lo, hi : int
        Range of ``order`` to process.
    k : int
        Candidates, ``min(candidates, n - 1)``.
    alpha2 : ndarray, shape (na,), float64
        Squares of the decreasing alpha schedule.
    min_nb : int
        Neighbors wanted.
    out : ndarray, shape (m, k), int64
        Output rows (nearest first), in the order of ``idx``.
    counts : ndarray, shape (m,), int64
        Output: neighbors per query.
    """
    na = alpha2.shape[0]
    snode, sdist, bufd, bufi = knn_scratch(tree, k)
    xs = np.empty((k, 3))
    ds = np.empty(k)
    ids = np.empty(k, np.int64)
    first = np.empty(k, np.int64)
    hist = np.empty(na + 1, np.int64)
    for s in range(lo, hi):
        t = order[s]
        p = idx[t]
        knn_point(points, tree, p, k, ds, ids, snode, sdist, bufd, bufi)
        for i in range(k):
            c = ids[i]
            xs[i, 0] = points[c, 0] - points[p, 0]
            xs[i, 1] = points[c, 1] - points[p, 1]
            xs[i, 2] = points[c, 2] - points[p, 2]
        for f in range(na + 1):
            hist[f] = 0
        for i in range(k):
            # first[i]: index of the first alpha at which no earlier candidate blocks q
            f = 0
            length = np.sqrt(ds[i])
            if length > 0.0:
                d = 0.5 * length
                d2 = d * d
                e0 = xs[i, 0] / length
                e1 = xs[i, 1] / length
                e2 = xs[i, 2] / length
                m0 = 0.5 * xs[i, 0]
                m1 = 0.5 * xs[i, 1]
                m2 = 0.5 * xs[i, 2]
                for j in range(i):
                    r0 = xs[j, 0] - m0
                    r1 = xs[j, 1] - m1
                    r2 = xs[j, 2] - m2
                    u = r0 * e0 + r1 * e1 + r2 * e2
                    w2 = r0 * r0 + r1 * r1 + r2 * r2 - u * u
                    if w2 < 0.0:
                        w2 = 0.0
                    while f < na and spheroid_blocks(u, w2, d2, alpha2[f]):
                        f += 1
                    if f == na:
                        break
            first[i] = f
            hist[f] += 1
        # the first alpha of the schedule giving enough neighbors, else the last one
        chosen = na - 1
        total = 0
        for f in range(na):
            total += hist[f]
            if total >= min_nb:
                chosen = f
                break
        cnt = 0
        for i in range(k):
            if first[i] <= chosen:
                out[t, cnt] = ids[i]
                cnt += 1
        counts[t] = cnt


@njit(cache=True, parallel=True)
def _egg_parallel(points, tree, idx, order, k, alpha2, min_nb, out, counts):
    """:func:`_egg_range` over all queries, blocks of :data:`BLOCK` queries in parallel."""
    m = idx.shape[0]
    nblocks = (m + BLOCK - 1) // BLOCK
    for blk in prange(nblocks):
        _egg_range(points, tree, idx, order, blk * BLOCK, min(m, (blk + 1) * BLOCK), k, alpha2,
                   min_nb, out, counts)


class EggFinder(TreeMixin, NeighborFinder):
    """Elliptic Gabriel Graph neighbors (Park, Shin & Choi), alpha lowered until enough.

    Neighbors of a query are listed nearest first.
    """

    name = "egg"
    PARAMS = (
        ParamSpec("candidates", int, 60, 2, 1000,
                  "nearest points examined (neighbors and possible blockers)"),
        ParamSpec("alpha_start", float, 0.7, 0.001, 1.0,
                  "first spheroid width across pq, as a fraction of |pq|/2 (1 = Gabriel)"),
        ParamSpec("alpha_step", float, 0.05, 0.001, 1.0,
                  "alpha is lowered by this step until enough neighbors are found"),
        ParamSpec("min_neighbors", int, 24, 1, 1000,
                  "alpha is lowered until at least this many neighbors are found"),
    )

    def examined(self) -> int:
        """Only the ``candidates`` nearest points are tested."""
        return self.params["candidates"]

    def validate(self, params: dict) -> None:
        where = f"method '{self.name}'"
        if params["alpha_step"] > params["alpha_start"]:
            raise ParameterError(
                f"{where}: alpha_step ({params['alpha_step']}) must be <= "
                f"alpha_start ({params['alpha_start']})")
        self.require_enough_candidates(params)
        if alpha_values(params["alpha_start"], params["alpha_step"]).size > MAX_ALPHAS:
            raise ParameterError(
                f"{where}: alpha_start / alpha_step gives more than {MAX_ALPHAS} alpha "
                f"values; use a larger alpha_step")

    @property
    def alphas(self) -> np.ndarray:
        """The alpha schedule, shape (na,), decreasing."""
        return alpha_values(self.params["alpha_start"], self.params["alpha_step"])

    def query(self, idx: np.ndarray, workers: int = 1) -> Neighborhoods:
        """EGG neighborhoods of ``points[idx]``; see the module docstring.

        Parameters
        ----------
        idx : ndarray, shape (m,), int64
            Query point indices.
        workers : int
            Threads for the numba kernel; results do not depend on it.

        Returns
        -------
        Neighborhoods
            CSR; at most ``candidates`` neighbors per query, nearest first.
        """
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        p = self.params
        alphas = self.alphas
        alpha2 = alphas * alphas
        n = self.points.shape[0]
        k = min(p["candidates"], n - 1)
        if k < 1:  # a single point: nobody to list
            return Neighborhoods(np.zeros(idx.size + 1, np.int64), np.zeros(0, np.int32))
        min_nb = p["min_neighbors"]
        tree = self.nbtree
        step = max(1, CHUNK_ENTRIES // k)
        parts = []
        for s in range(0, idx.size, step):
            sub = idx[s:s + step]
            order = query_order(tree, sub)
            out = np.empty((sub.size, k), np.int64)
            counts = np.zeros(sub.size, np.int64)
            with numba_threads(workers) as parallel:
                if parallel:
                    _egg_parallel(self.nbpoints, tree, sub, order, k, alpha2, min_nb, out, counts)
                else:
                    _egg_range(self.nbpoints, tree, sub, order, 0, sub.size, k, alpha2, min_nb,
                               out, counts)
            parts.append(to_csr(out, counts, n))
        return Neighborhoods.concatenate(parts)
