"""The fixed-method estimator: a named neighborhood method (knn, tc, egg, mesh) and fit model
(implicit, monge, adaptive, nfr), run chunk by chunk over the query points.
"""

from __future__ import annotations

import time

import numpy as np

from ..fitting import fit_neighborhoods, stage1_normals
from ..fitting.uncertainty import design_std
from ..neighborhoods import make_finder
from ..neighborhoods.kdtree import build_tree, knn_parallel
from ..orientation import first_neighbors
from ..uncertainty import FIT_CALIBRATION, with_floor

# Query points per chunk (``estimate``'s default chunk_size): one chunk's neighborhoods exist
# at a time.
DEFAULT_CHUNK = 32768


def fit_chunks(spts, finder, res, graph, fit, fit_opts, nthreads, chunk_size, progress,
               timings, query=None, track_reach: bool = False):
    """Neighborhoods and fits of a neighborhood method, chunk by chunk, into ``res``.

    ``res`` and ``graph`` rows follow ``query`` (default: every point). Returns each query
    point's reach when ``track_reach`` (else None).
    """
    n = spts.shape[0]
    query = np.arange(n, dtype=np.int64) if query is None else query
    m = query.shape[0]
    stage1 = stage1_radius = None
    reach = np.empty(m) if track_reach else None
    timings.update(neighbors=0.0, fit=0.0)
    extra_k = finder.examined() if track_reach else 0
    # one tree for every reach distance of this block
    tree = build_tree(spts) if track_reach and (extra_k or fit == "nfr") else None
    if fit == "nfr":
        t0 = time.perf_counter()
        stage1 = stage1_normals(spts, make_finder(spts, "knn", k=fit_opts["normal_k"]),
                                chunk_size, nthreads)
        if track_reach:
            stage1_radius = kth_distance(spts, fit_opts["normal_k"], tree=tree)
        timings["stage1_normals"] = time.perf_counter() - t0
    for start in range(0, m, chunk_size):
        stop = min(start + chunk_size, m)
        q = query[start:stop]
        t0 = time.perf_counter()
        nbhd = finder.query(q, workers=nthreads)
        t1 = time.perf_counter()
        out = fit_neighborhoods(spts, q, nbhd, fit, fit_opts["solver"],
                                fit_opts["include_self"], stage1, fit_opts["clean_residual"])
        timings["neighbors"] += t1 - t0
        timings["fit"] += time.perf_counter() - t1
        sl = slice(start, stop)
        res.k1[sl], res.k2[sl], res.residual[sl], res.status[sl] = \
            out.k1, out.k2, out.residual, out.status
        res.normals[sl], res.dir1[sl], res.dir2[sl] = out.normals, out.dir1, out.dir2
        res.neighbor_count[sl] = nbhd.sizes()
        t1 = time.perf_counter()
        design_std(spts, q, nbhd.indptr, nbhd.indices, bool(fit_opts["include_self"]),
                   out.dir1, out.dir2, out.residual, out.status, FIT_CALIBRATION[fit],
                   res.k1_std[sl], res.k2_std[sl], res.mean_std[sl])
        for name in ("k1_std", "k2_std", "mean_std"):
            getattr(res, name)[sl] = with_floor(getattr(res, name)[sl], out.k1, out.k2)
        timings["std"] = timings.get("std", 0.0) + time.perf_counter() - t1
        if graph is not None:
            graph[sl] = first_neighbors(nbhd)
        if reach is not None:
            reach[sl] = neighborhood_reach(spts, q, nbhd, stage1_radius)
            if extra_k:  # candidate-based methods examine more points than they keep
                reach[sl] = np.maximum(reach[sl], kth_distance(spts, extra_k, q, tree))
        if progress is not None:
            progress(stop, m)
    return reach


def kth_distance(points: np.ndarray, k: int, query=None, tree=None) -> np.ndarray:
    """Distance of each query point (default: all) to its k-th nearest other point."""
    n = points.shape[0]
    query = np.arange(n, dtype=np.int64) if query is None else query
    k = min(k, n - 1)
    tree = build_tree(points) if tree is None else tree
    out = np.empty(query.shape[0])
    for start in range(0, query.shape[0], DEFAULT_CHUNK):
        q = query[start:start + DEFAULT_CHUNK]
        nbr = np.empty((q.shape[0], k), np.int32)
        d2 = np.empty((q.shape[0], k))
        knn_parallel(points, tree, q, k, nbr, d2)
        out[start:start + q.shape[0]] = np.sqrt(d2[:, -1])
    return out


def neighborhood_reach(points, query, nbhd, radius=None) -> np.ndarray:
    """Largest distance from each query point to a neighbor (plus the neighbor's own
    ``radius`` when given, and the query point's)."""
    sizes = nbhd.sizes()
    rows = np.repeat(np.arange(query.shape[0]), sizes)
    d = np.linalg.norm(points[nbhd.indices] - points[query[rows]], axis=1)
    if radius is not None:
        d += radius[nbhd.indices]
    out = np.zeros(query.shape[0])
    np.maximum.at(out, rows, d)
    if radius is not None:
        out = np.maximum(out, radius[query])
    return out
