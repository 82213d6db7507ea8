"""Territory Claiming neighborhoods (``tc``, DESIGN.md section 4.1).

Each accepted neighbor q of p claims a territory behind it (the beta-lune); a later candidate
inside the territory of an accepted point is rejected. The result is a directionally balanced
neighbor set. The beta sweep is done in one pass over the candidates: every candidate carries
a bit mask over the beta values for which it is accepted, so the greedy pass runs once for all
betas instead of once per beta.

Reading of the ring growth (step 4 of the design): ring r takes as candidates the
``candidates`` nearest points of the pool left after removing every point gathered by rings
1..r-1 (points rejected by an earlier ring stay in the pool and may be accepted later). Within
ring r only the points accepted in ring r claim territory; the points of earlier rings do not,
so the nearest candidate of each ring is always accepted and every ring adds at least one point.
The beta choice is made per ring. Since each ring needs at most the ``candidates`` nearest points
outside fewer than ``min_neighbors`` gathered ones, the ``candidates + min_neighbors - 1``
nearest points of p hold every ring; the growth stops early when the pool is exhausted.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..errors import ParameterError
from ..params import ParamSpec
from .base import NeighborFinder, Neighborhoods
from .candidates import BLOCK, CHUNK_ENTRIES, TreeMixin, numba_threads, to_csr
from .kdtree import knn_point, knn_scratch, query_order

# Accept masks are int64 bit sets over the beta values.
MAX_BETAS = 62


def beta_values(beta_min: float, beta_max: float, beta_step: float) -> np.ndarray:
    """The beta values of a sweep: ``round(beta_min + i * beta_step, 10)`` up to ``beta_max``.

    Returns
    -------
    ndarray, shape (nb,), float64
        Increasing; empty when ``beta_min > beta_max``.
    """
    top = round(beta_max, 10)
    out = []
    i = 0
    while True:
        b = round(beta_min + i * beta_step, 10)
        if b > top:
            break
        out.append(b)
        i += 1
        if i > 10 * MAX_BETAS:  # enough to know the sweep is too long
            break
    return np.asarray(out, dtype=np.float64)


@njit(cache=True, inline="always")
def lune_claims(aa, ax, xx, beta):
    """True when an accepted q claims candidate c (c lies in q's territory).

    With ``a = q - p`` and ``x = c - p``, q claims c iff
    ``|a|^2 < beta (a.x)`` and ``|a|^2 - (2 - beta)(a.x) + (1 - beta)|x|^2 < 0``.
    Written without branches so the kernel's loop over the betas vectorizes; replace this
    function to try another territory shape.

    Parameters
    ----------
    aa : float
        ``|a|^2``.
    ax : float
        ``a . x``.
    xx : float
        ``|x|^2``.
    beta : float
        Territory size (1: Gabriel, 2: relative neighborhood).
    """
    return (aa < beta * ax) & (aa - (2.0 - beta) * ax + (1.0 - beta) * xx < 0.0)


@njit(cache=True)
def _tc_range(points, tree, idx, order, lo, hi, k, betas, ncand, min_nb, out,
              counts):
    """Territory Claiming for the queries ``idx[order[lo:hi]]``.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
    tree : tuple
        :func:`.kdtree.build_tree` over ``points``.
    idx : ndarray, shape (m,), int64
        Query points.
    order : ndarray, shape (m,), int64
        Processing order of the queries (any permutation; results do not depend on it).
    lo, hi : int
        Range of ``order`` to process.
    k : int
        Nearest points loaded per query, ``min(ncand + min_nb - 1, n - 1)``.
    betas : ndarray, shape (nb,), float64
        Increasing beta values, ``nb <= 62``.
    ncand : int
        Candidates per ring.
    min_nb : int
        Rings are added until at least this many neighbors are gathered.
    out : ndarray, shape (m, k), int64
        Output rows, in the order of ``idx``.
    counts : ndarray, shape (m,), int64
        Output: neighbors per query.
    """
    nb = betas.shape[0]
    full = (np.int64(1) << nb) - 1
    snode, sdist, bufd, bufi = knn_scratch(tree, k)
    xs = np.empty((k, 3))
    ds = np.empty(k)
    rd = np.empty(k)
    ids = np.empty(k, np.int64)
    gathered = np.zeros(k, np.bool_)
    pos = np.empty(ncand, np.int64)
    mask = np.empty(ncand, np.int64)
    a0 = np.empty(ncand)
    a1 = np.empty(ncand)
    a2 = np.empty(ncand)
    aas = np.empty(ncand)
    am = np.empty(ncand, np.int64)
    ar = np.empty(ncand)
    sums = np.empty(nb)
    cnts = np.empty(nb)
    for s in range(lo, hi):
        t = order[s]
        p = idx[t]
        knn_point(points, tree, p, k, ds, ids, snode, sdist, bufd, bufi)
        for i in range(k):
            c = ids[i]
            xs[i, 0] = points[c, 0] - points[p, 0]
            xs[i, 1] = points[c, 1] - points[p, 1]
            xs[i, 2] = points[c, 2] - points[p, 2]
            rd[i] = np.sqrt(ds[i])
            gathered[i] = False
        total = 0
        while total < min_nb:
            # this ring's candidates: the nearest points not gathered yet
            nc = 0
            for i in range(k):
                if not gathered[i]:
                    pos[nc] = i
                    nc += 1
                    if nc == ncand:
                        break
            if nc == 0:
                break  # pool exhausted
            # one greedy pass for all betas: mask[i] = betas for which candidate i is accepted
            # (accepted points of this ring are copied to a0..am: coordinates, |a|^2, mask)
            na = 0
            for i in range(nc):
                ci = pos[i]
                x0 = xs[ci, 0]
                x1 = xs[ci, 1]
                x2 = xs[ci, 2]
                xx = ds[ci]
                live = full
                for j in range(na):
                    if (am[j] & live) == 0:
                        continue
                    ax = a0[j] * x0 + a1[j] * x1 + a2[j] * x2
                    aa = aas[j]
                    claim = np.int64(0)
                    for b in range(nb):
                        claim |= np.int64(lune_claims(aa, ax, xx, betas[b])) << b
                    live &= ~(claim & am[j])
                    if live == 0:
                        break
                mask[i] = live
                if live != 0:
                    a0[na] = x0
                    a1[na] = x1
                    a2[na] = x2
                    aas[na] = xx
                    ar[na] = rd[ci]
                    am[na] = live
                    na += 1
            # beta with the smallest mean distance; ties go to the larger beta
            for b in range(nb):
                sums[b] = 0.0
                cnts[b] = 0.0
            for j in range(na):
                r = ar[j]
                mk = am[j]
                for b in range(nb):
                    bit = np.float64((mk >> b) & 1)
                    sums[b] += r * bit
                    cnts[b] += bit
            best = nb - 1
            best_mean = np.inf
            for b in range(nb - 1, -1, -1):
                mean = sums[b] / cnts[b]
                if mean < best_mean:
                    best_mean = mean
                    best = b
            for i in range(nc):
                if (mask[i] >> best) & 1:
                    out[t, total] = ids[pos[i]]
                    gathered[pos[i]] = True
                    total += 1
        counts[t] = total


@njit(cache=True, parallel=True)
def _tc_parallel(points, tree, idx, order, k, betas, ncand, min_nb, out, counts):
    """:func:`_tc_range` over all queries, blocks of :data:`BLOCK` queries in parallel."""
    m = idx.shape[0]
    nblocks = (m + BLOCK - 1) // BLOCK
    for blk in prange(nblocks):
        _tc_range(points, tree, idx, order, blk * BLOCK, min(m, (blk + 1) * BLOCK), k, betas,
                  ncand, min_nb, out, counts)


class TerritoryFinder(TreeMixin, NeighborFinder):
    """Territory Claiming neighbors (Khameneifar & Feng), grown ring by ring.

    Neighbors of a query are listed ring by ring, in order of acceptance (increasing
    distance within a ring).
    """

    name = "tc"
    PARAMS = (
        ParamSpec("candidates", int, 60, 2, 1000,
                  "nearest pool points examined per ring"),
        ParamSpec("beta_min", float, 1.0, 0.1, 10.0,
                  "smallest territory size tried (1 = Gabriel lune)"),
        ParamSpec("beta_max", float, 2.0, 0.1, 10.0,
                  "largest territory size tried (2 = relative-neighborhood lune)"),
        ParamSpec("beta_step", float, 0.1, 0.001, 10.0,
                  "step between the beta values tried"),
        ParamSpec("min_neighbors", int, 24, 1, 1000,
                  "rings are added until at least this many neighbors are gathered"),
    )

    def examined(self) -> int:
        """Every ring lies within the ``candidates + min_neighbors - 1`` nearest points."""
        return self.params["candidates"] + self.params["min_neighbors"] - 1

    def validate(self, params: dict) -> None:
        where = f"method '{self.name}'"
        if params["beta_min"] > params["beta_max"]:
            raise ParameterError(
                f"{where}: beta_min ({params['beta_min']}) must be <= "
                f"beta_max ({params['beta_max']})")
        self.require_enough_candidates(params)
        nb = beta_values(params["beta_min"], params["beta_max"], params["beta_step"]).size
        if nb > MAX_BETAS:
            raise ParameterError(
                f"{where}: beta_min..beta_max in steps of beta_step gives more than "
                f"{MAX_BETAS} beta values; use a larger beta_step")

    @property
    def betas(self) -> np.ndarray:
        """The beta values tried, shape (nb,)."""
        p = self.params
        return beta_values(p["beta_min"], p["beta_max"], p["beta_step"])

    def query(self, idx: np.ndarray, workers: int = 1) -> Neighborhoods:
        """Territory Claiming neighborhoods of ``points[idx]``; see the module docstring.

        Parameters
        ----------
        idx : ndarray, shape (m,), int64
            Query point indices.
        workers : int
            Threads for the numba kernel; results do not depend on it.

        Returns
        -------
        Neighborhoods
            CSR; at most ``candidates + min_neighbors - 1`` neighbors per query.
        """
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        p = self.params
        ncand, min_nb = p["candidates"], p["min_neighbors"]
        betas = self.betas
        n = self.points.shape[0]
        k = min(ncand + min_nb - 1, n - 1)
        if k < 1:  # a single point: nobody to list
            return Neighborhoods(np.zeros(idx.size + 1, np.int64), np.zeros(0, np.int32))
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
                    _tc_parallel(self.nbpoints, tree, sub, order, k, betas, ncand, min_nb,
                                 out, counts)
                else:
                    _tc_range(self.nbpoints, tree, sub, order, 0, sub.size, k, betas, ncand,
                              min_nb, out, counts)
            parts.append(to_csr(out, counts, n))
        return Neighborhoods.concatenate(parts)
