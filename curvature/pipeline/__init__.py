"""``curvature.estimate``: neighborhoods, quadric fits and orientation for a whole cloud.

Work goes through the cloud in chunks of query points so memory stays bounded: only one chunk's
neighborhoods exist at a time, and the outputs are the only per-point arrays kept.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass

import numba
import numpy as np

from .attributes import carry_input, file_viewpoint, orientation_rule
from ..estimators.auto import AUTO_PARAMS, AutoRun
from ..cloud import PointCloud
from ..errors import ParameterError
from ..fitting import FIT_PARAMS, FITS, fit_neighborhoods, resolve_fit, stage1_normals
from ..neighborhoods import FINDERS, make_finder
from ..neighborhoods.kdtree import build_tree, knn_parallel
from ..orientation import (
    ORIENT_K,
    apply_signs,
    first_neighbors,
    signs_auto,
    signs_from_normals,
    signs_from_viewpoint,
)
from ..params import resolve_params
from ..result import CurvatureResult
from .spatial_order import inverse_permutation, morton_order
from ..validation import as_faces, as_points, as_vectors

ORIENTATIONS = ("auto", "normals", "viewpoint")
DEFAULT_METHOD = "auto"
# Fit of the neighborhood methods when none is named: the implicit quadric where it fits the
# neighborhood (exact on quadrics), the height function where noise would make the implicit
# one speckle (real scans); measured in docs/defaults.md.
DEFAULT_FIT = "adaptive"
#: Named configurations: ``estimate(points, preset="paper")``.
PRESETS = {
    # The paper's own setting: Territory Claiming grown to 10 neighbors from 30 candidates,
    # implicit quadric.
    "paper": {"method": "tc", "fit": "implicit", "min_neighbors": 10, "candidates": 30},
}
DEFAULT_CHUNK = 32768
# Clouds above TILE_ABOVE points are processed in tiles of AUTO_TILE_POINTS (tile_points=None):
# a tile's working set is about 550 bytes per tile point, beside about 200 per cloud point.
TILE_ABOVE = 2_000_000
AUTO_TILE_POINTS = 1_000_000
# Tiles handed to an executor: small enough to spread over a cluster, large enough that the
# halo (a few spacings around the tile) stays a small share of the work.
EXECUTOR_TILE_POINTS = 250_000
MIN_TILE_POINTS = 1000
ProgressFn = Callable[[int, int], None]


def resolve_workers(workers) -> int:
    """Number of threads to use: ``None`` means every core numba may use."""
    limit = numba.config.NUMBA_NUM_THREADS
    if workers is None:
        return max(1, min(limit, os.cpu_count() or 1))
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise ParameterError(f"workers must be a whole number >= 1, got {workers!r}")
    return int(min(workers, limit))


@contextmanager
def numba_threads(count: int):
    """Run numba's parallel loops with ``count`` threads, restoring the previous count."""
    before = numba.get_num_threads()
    numba.set_num_threads(count)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def resolve_orientation(orientation, normals, viewpoint) -> str:
    """Pick the orientation mode (DESIGN.md 5) and check that its input is present."""
    if orientation is None:
        return "normals" if normals is not None else "viewpoint" if viewpoint is not None \
            else "auto"
    if orientation not in ORIENTATIONS:
        raise ParameterError(
            f"unknown orientation {orientation!r}; choose one of {list(ORIENTATIONS)}")
    if orientation == "normals" and normals is None:
        raise ParameterError("orientation 'normals' needs per-point normals")
    if orientation == "viewpoint" and viewpoint is None:
        raise ParameterError("orientation 'viewpoint' needs a viewpoint (x, y, z)")
    return orientation


def check_viewpoint(viewpoint, n: int) -> np.ndarray | None:
    """A viewpoint as a finite float64 array: shape (3,), or (n, 3) for one per point."""
    if viewpoint is None:
        return None
    try:
        vp = np.asarray(viewpoint, np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"viewpoint must be three numbers, got {viewpoint!r}") from None
    if vp.ndim == 2 and vp.shape[1] == 3 and vp.shape[0] != 1:
        if vp.shape[0] != n:
            raise ParameterError(f"per-point viewpoints must have shape ({n}, 3) to match "
                                 f"the {n} points, got {vp.shape}")
        bad = np.flatnonzero(~np.isfinite(vp).all(axis=1))
        if bad.size:
            raise ParameterError(f"the viewpoint of point {int(bad[0])} is not finite")
        return vp
    vp = vp.reshape(-1)
    if vp.shape != (3,) or not np.isfinite(vp).all():
        raise ParameterError(f"viewpoint must be three finite numbers (or one row per point), "
                             f"got {viewpoint!r}")
    return vp


def split_params(params: dict) -> tuple[dict, dict]:
    """Separate fit parameters (solver, include_self) from neighborhood method parameters."""
    fit_names = {s.name for s in FIT_PARAMS}
    fit_params = {k: v for k, v in params.items() if k in fit_names}
    method_params = {k: v for k, v in params.items() if k not in fit_names}
    return fit_params, method_params


def apply_preset(preset, method, fit, params: dict) -> tuple[str, str | None, dict]:
    """Method, fit and parameters after a named preset; explicit arguments must agree with it.

    Parameters given beside the preset override the preset's own values.
    """
    if preset is None:
        return (DEFAULT_METHOD if method is None else method), fit, params
    if preset not in PRESETS:
        raise ParameterError(f"unknown preset {preset!r}; choose one of {sorted(PRESETS)}")
    conf = dict(PRESETS[preset])
    p_method, p_fit = conf.pop("method"), conf.pop("fit")
    for name, given, wanted in (("method", method, p_method), ("fit", fit, p_fit)):
        if given is not None and given != wanted:
            raise ParameterError(
                f"preset {preset!r} uses {name} {wanted!r}; {name} {given!r} contradicts it")
    return p_method, p_fit, {**conf, **params}


METHODS = ("auto", *FINDERS)


def estimate(points, method: str | None = None, *, fit: str | None = None, preset=None,
             orientation=None, normals=None, viewpoint=None, faces=None, workers=None,
             progress: ProgressFn | None = None, chunk_size: int = DEFAULT_CHUNK,
             tile_points: int | None = None, executor=None, **params) -> CurvatureResult:
    """Per-point curvature of a cloud by local surface fitting.

    Parameters
    ----------
    points : array_like, shape (n, 3), or PointCloud
        Coordinates. A PointCloud also supplies normals and faces unless given here.
    method : {"auto", "knn", "tc", "egg", "mesh"}, optional
        "auto" (the default) measures the cloud's noise and spacing and picks model and scale
        itself (:mod:`curvature.estimators.auto`; parameters ``k``, ``normal_k``, ``noise_threshold``).
        The others are the neighborhood methods of DESIGN.md 4.1-4.4; their parameters go in
        ``**params``.
    fit : {"adaptive", "implicit", "monge", "nfr"}, optional
        Fit model of the neighborhood methods (DESIGN.md 4.5). The default, "adaptive",
        keeps the implicit quadric where its RMS residual is at most ``clean_residual``
        (0.01) of the RMS neighbor distance, which makes it exact on quadrics, and fits the
        height function ("monge") elsewhere, which stays sane on noisy scans (see
        docs/defaults.md). ``solver="taubin"|"algebraic"`` selects the implicit solver.
        "nfr" (normal-field regression) regresses PCA normals (``normal_k`` neighbors) on
        position over the neighborhood; it is made for large neighborhoods on noisy data.
        Method "auto" chooses its own fit and takes none.
    preset : {"paper"}, optional
        A named configuration: "paper" is the paper's Territory Claiming with 10 neighbors and
        the implicit quadric. Parameters given beside it override its values.
    orientation : {"auto", "normals", "viewpoint"}, optional
        How normal signs are fixed; by default "normals" when normals are given, "viewpoint"
        when a viewpoint is given, else "auto".
    normals : array_like, shape (n, 3), optional
        Reference normals (e.g. from the scanner); estimated normals are flipped to agree.
    viewpoint : array_like, shape (3,) or (n, 3), optional
        Scanner position, or one per point (e.g. each point's scan origin in a file of
        several scans); normals are turned to face it.
    faces : array_like, shape (m, 3), optional
        Mesh triangles for ``method="mesh"``; kept in the result.
    workers : int, optional
        Threads to use (default: all cores). Results are identical for any value.
    progress : callable, optional
        ``progress(done, total)`` after each chunk of work. An exception raised by it aborts
        the run (used for cancellation).
    chunk_size : int
        Query points per chunk.
    tile_points : int, optional
        Split the cloud into spatial tiles of about this many points, each computed with a
        halo that is checked to hold everything its points depend on (:mod:`curvature.pipeline.tiling`);
        results are identical to an untiled run. Default: tiles of 1M points above 2M points
        (250k with an ``executor``); 0 never tiles.
    executor : object, optional
        Where tiles are computed: anything whose ``submit(fn, arg)`` returns a future with
        ``result()``, ``cancel()`` and ``add_done_callback()`` (a
        ``concurrent.futures.Executor``, a Dask ``distributed.Client``). The cloud is then
        always tiled; measurements, assembly and orientation stay in this process. Results
        are identical to a local run.
    **params
        Method parameters (e.g. ``k=24`` for knn) and fit parameters (``solver``,
        ``include_self``).

    Returns
    -------
    CurvatureResult
        ``info`` records the method, parameters, fit, timings and, for "auto", the measured
        plan (spacing, relative noise, the branch taken).

    Raises
    ------
    CurvatureInputError
        Bad cloud (shape, empty, fewer than 10 points, NaN/Inf) or bad normals/faces.
    ParameterError
        Unknown method, fit, preset, orientation or parameter, or a value out of bounds.
    """
    t_start = time.perf_counter()
    cloud, file_normals, vp_source = None, False, None
    if isinstance(points, PointCloud):
        cloud = points
        file_normals = normals is None and cloud.normals is not None
        normals = cloud.normals if normals is None else normals
        file_vp = file_viewpoint(cloud, orientation, normals, viewpoint)
        if file_vp is not None:
            viewpoint, vp_source = file_vp, cloud.viewpoint_source
        faces = cloud.faces if faces is None else faces
        points = cloud.points
    pts = as_points(points)
    n = pts.shape[0]
    ref_normals = None if normals is None else as_vectors(normals, n, "normals")
    tri = as_faces(faces, n)
    vp = check_viewpoint(viewpoint, n)
    req = resolve_request(preset, method, fit, params, orientation, ref_normals, vp, workers,
                          chunk_size)
    if executor is not None and not callable(getattr(executor, "submit", None)):
        raise ParameterError(f"executor must have a submit(fn, arg) method, got {executor!r}")
    tiles = resolve_tile_points(tile_points, n, executor is not None)

    # Work on a Z-ordered copy so neighbor reads stay local; every per-point computation is
    # unchanged, and the outputs are put back in input order at the end.
    order = morton_order(pts)
    inv = inverse_permutation(order)
    spts = np.ascontiguousarray(pts[order])
    s_normals = None if ref_normals is None else ref_normals[order]
    s_vp = vp[order] if vp is not None and vp.ndim == 2 else vp
    s_faces = None if tri is None else inv[tri]
    del order
    with numba_threads(req.workers):
        if tiles is None:
            block = compute_block(spts, s_faces, req, progress=progress)
            res, graph, info, timings = block.result, block.graph, block.info, block.timings
        else:
            from .tiling import run_tiled

            res, graph, info, timings = run_tiled(spts, s_faces, req, tiles, progress,
                                                  executor)
        t0 = time.perf_counter()
        orient(res, req.mode, s_normals, s_vp, graph)
        timings["orientation"] = time.perf_counter() - t0
    del graph
    res = unpermute(res, inv, pts, tri)
    res.mean[:] = 0.5 * (res.k1 + res.k2)
    res.gaussian[:] = res.k1 * res.k2
    timings["total"] = time.perf_counter() - t_start
    res.info = {
        **info, "preset": preset, "orientation": req.mode, "workers": req.workers, "points": n,
        "faces": 0 if tri is None else int(tri.shape[0]),
        "status_counts": res.status_counts(), "timings": timings,
        "orientation_rule": orientation_rule(req.mode, from_file=vp_source,
                                             normals_from_file=file_normals),
    }
    if vp is not None and vp.ndim == 1:
        res.info["viewpoint"] = vp.tolist()
    return res if cloud is None else carry_input(res, cloud)


@dataclass(frozen=True)
class Request:
    """Everything ``estimate`` was asked for, checked (picklable: tiles travel with it)."""

    method: str
    fit: str | None
    fit_opts: dict
    method_params: dict
    auto_params: dict
    mode: str
    workers: int
    chunk_size: int


def resolve_request(preset, method, fit, params, orientation, ref_normals, viewpoint, workers,
                    chunk_size) -> Request:
    """Check method, fit, parameters, orientation, workers and chunk size."""
    method, fit, params = apply_preset(preset, method, fit, params)
    if method not in METHODS:
        raise ParameterError(f"unknown method {method!r}; choose one of {sorted(METHODS)}")
    mode = resolve_orientation(orientation, ref_normals, viewpoint)
    fit_opts, method_params, auto_params = {}, {}, {}
    if method == "auto":
        if fit is not None:
            raise ParameterError(
                f"method 'auto' chooses its own fit; fit {fit!r} needs a neighborhood method "
                f"({', '.join(sorted(FINDERS))})")
        auto_params = resolve_params(AUTO_PARAMS, params, "method 'auto'")
    else:
        fit = DEFAULT_FIT if fit is None else fit
        fit_params, method_params = split_params(params)
        fit_opts = resolve_fit(fit, fit_params)
    nthreads = resolve_workers(workers)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise ParameterError(f"chunk_size must be a whole number >= 1, got {chunk_size!r}")
    return Request(method, fit, fit_opts, method_params, auto_params, mode, nthreads,
                   chunk_size)


def resolve_tile_points(tile_points, n: int, executor: bool = False) -> int | None:
    """Core points per tile, or None to run the cloud as one block.

    ``None`` tiles clouds larger than :data:`TILE_ABOVE`; 0 never tiles. With an
    executor the cloud is always tiled, by default in tiles of :data:`EXECUTOR_TILE_POINTS`
    (0: one tile).
    """
    if tile_points is not None and (
            isinstance(tile_points, bool) or not isinstance(tile_points, int | np.integer)
            or tile_points < 0):
        raise ParameterError(f"tile_points must be a whole number >= 0, got {tile_points!r}")
    if executor:
        size = EXECUTOR_TILE_POINTS if tile_points is None else int(tile_points) or n
        return max(min(size, n), min(MIN_TILE_POINTS, n))
    if tile_points is None:
        return AUTO_TILE_POINTS if n > TILE_ABOVE else None
    if tile_points == 0 or tile_points >= n:
        return None
    return max(int(tile_points), MIN_TILE_POINTS)


@dataclass
class Block:
    """Results of :func:`compute_block` for its query points (rows in query order).

    Attributes
    ----------
    result : CurvatureResult
        Unoriented curvature of the query points (mean and gaussian not yet filled).
    graph : ndarray, shape (m, ORIENT_K), int32, or None
        First neighbors of each query point (block indices), for orientation "auto".
    reach : ndarray, shape (m,), or None
        With ``track_reach``: a distance from each query point within which lies every point
        its result depends on.
    info, timings : dict
    """

    result: CurvatureResult
    graph: np.ndarray | None
    reach: np.ndarray | None
    info: dict
    timings: dict


def compute_block(spts, s_faces, req: Request, query=None, *, progress=None, plan=None,
                  mesh_graph=None, track_reach: bool = False) -> Block:
    """Unoriented curvature of ``query`` points of a Z-ordered block of points.

    Parameters
    ----------
    spts : ndarray, shape (n, 3)
        The block's points (a whole cloud, or a tile with its halo), in Z-order.
    s_faces : ndarray, shape (f, 3), optional
        Faces in block indices.
    req : Request
    query : ndarray, shape (m,), int64, optional
        Block indices to compute (default: all, in order).
    progress : callable, optional
    plan : AutoPlan, optional
        The whole cloud's plan for method "auto" (measured on the block if not given).
    mesh_graph : tuple of ndarray, optional
        The whole cloud's vertex graph restricted to the block, for method "mesh".
    track_reach : bool
        Also return each query point's reach (see :class:`Block`).
    """
    n = spts.shape[0]
    query = np.arange(n, dtype=np.int64) if query is None else np.asarray(query, np.int64)
    want_graph = req.mode == "auto"
    timings: dict = {}
    if req.method == "auto":
        res = empty_result(spts, s_faces)
        graph = np.empty((n, ORIENT_K), np.int32) if want_graph else None
        run = AutoRun(spts, req.auto_params, req.chunk_size, progress, plan=plan,
                      track_reach=track_reach)
        run.run(res, graph, ORIENT_K)
        timings.update(run.timings)
        info = {"method": "auto", "params": req.auto_params,
                "fit": "implicit" if run.plan.clean else "nfr", "plan": run.plan.to_dict()}
        if query.shape[0] != n or np.any(query != np.arange(n)):
            res = select_rows(res, query, spts[query])
            graph = None if graph is None else graph[query]
        reach = None if run.reach is None else run.reach[query]
        return Block(res, graph, reach, info, timings)
    finder = make_finder(spts, req.method, faces=s_faces, **req.method_params)
    if mesh_graph is not None:
        finder.use_graph(mesh_graph)
    res = empty_result(spts[query], None)
    graph = np.empty((query.shape[0], ORIENT_K), np.int32) if want_graph else None
    reach = fit_chunks(spts, finder, res, graph, req.fit, req.fit_opts, req.workers,
                       req.chunk_size, progress, timings, query, track_reach)
    res.faces = s_faces if query.shape[0] == n else None
    info = {"method": req.method, "params": dict(finder.params), "fit": req.fit,
            **req.fit_opts}
    return Block(res, graph, reach, info, timings)


def select_rows(res: CurvatureResult, rows: np.ndarray, points: np.ndarray) -> CurvatureResult:
    """The result restricted to ``rows``."""
    return CurvatureResult(points=points, faces=None,
                           **{name: arr[rows] for name, arr in res.fields().items()})


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


# Result fields computed from k1 and k2 at the very end (never written before, so their pages
# cost no memory while a big cloud is computed).
DERIVED = ("mean", "gaussian")


def empty_result(pts: np.ndarray, faces) -> CurvatureResult:
    """A result with every output array allocated (filled by the chunks)."""
    n = pts.shape[0]
    return CurvatureResult(
        points=pts, k1=np.empty(n), k2=np.empty(n), mean=np.empty(n), gaussian=np.empty(n),
        normals=np.empty((n, 3)), dir1=np.empty((n, 3)), dir2=np.empty((n, 3)),
        neighbor_count=np.empty(n, np.int32), status=np.empty(n, np.int8),
        residual=np.empty(n), faces=faces)


def unpermute(res: CurvatureResult, inv: np.ndarray, pts: np.ndarray, faces) -> CurvatureResult:
    """The result of the Z-ordered cloud in input order (``inv`` from inverse_permutation).

    Fields are reordered one at a time, so at most one extra field is held at once. Mean and
    Gaussian curvature are derived afterwards, so they are left unfilled here.
    """
    fields = res.fields()
    for name in list(fields):
        if name in DERIVED:
            fields[name] = np.empty(inv.shape[0])
        else:
            fields[name] = fields[name][inv]
        setattr(res, name, fields[name])
    return CurvatureResult(points=pts, faces=faces, **fields)


def orient(res: CurvatureResult, mode: str, ref_normals, viewpoint, graph) -> None:
    """Fix the sign of every fitted normal, flipping curvatures and directions with it.

    ``graph`` (n, ORIENT_K) holds each point's first neighbors for mode "auto".
    """
    if mode == "normals":
        signs = signs_from_normals(res.normals, ref_normals)
    elif mode == "viewpoint":
        signs = signs_from_viewpoint(res.points, res.normals, viewpoint)
    else:
        signs = signs_auto(res.points, res.normals, graph)
    apply_signs(signs, res.k1, res.k2, res.normals, res.dir1, res.dir2)


__all__ = ["FITS", "METHODS", "ORIENTATIONS", "PRESETS", "estimate"]
