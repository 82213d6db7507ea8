"""``curvature.estimate``: neighborhoods, quadric fits and orientation for a whole cloud.

Work goes through the cloud in chunks of query points so memory stays bounded: only one chunk's
neighborhoods exist at a time, and the outputs are the only per-point arrays kept.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from contextlib import contextmanager

import numba
import numpy as np

from .cloud import PointCloud
from .errors import ParameterError
from .fitting import FIT_PARAMS, FITS, fit_neighborhoods, resolve_fit, stage1_normals
from .neighborhoods import make_finder
from .orientation import (
    ORIENT_K,
    apply_signs,
    first_neighbors,
    signs_auto,
    signs_from_normals,
    signs_from_viewpoint,
)
from .result import CurvatureResult
from .spatial_order import inverse_permutation, morton_order
from .validation import as_faces, as_points, as_vectors

ORIENTATIONS = ("auto", "normals", "viewpoint")
DEFAULT_CHUNK = 32768
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


def check_viewpoint(viewpoint) -> np.ndarray | None:
    """A viewpoint as a finite float64 (3,) array."""
    if viewpoint is None:
        return None
    try:
        vp = np.asarray(viewpoint, np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError(f"viewpoint must be three numbers, got {viewpoint!r}") from None
    if vp.shape != (3,) or not np.isfinite(vp).all():
        raise ParameterError(f"viewpoint must be three finite numbers, got {viewpoint!r}")
    return vp


def split_params(params: dict) -> tuple[dict, dict]:
    """Separate fit parameters (solver, include_self) from neighborhood method parameters."""
    fit_names = {s.name for s in FIT_PARAMS}
    fit_params = {k: v for k, v in params.items() if k in fit_names}
    method_params = {k: v for k, v in params.items() if k not in fit_names}
    return fit_params, method_params


def estimate(points, method: str = "knn", *, fit: str = "implicit", orientation=None,
             normals=None, viewpoint=None, faces=None, workers=None,
             progress: ProgressFn | None = None, chunk_size: int = DEFAULT_CHUNK,
             **params) -> CurvatureResult:
    """Per-point curvature of a cloud by local quadric fitting.

    Parameters
    ----------
    points : array_like, shape (n, 3), or PointCloud
        Coordinates. A PointCloud also supplies normals and faces unless given here.
    method : {"knn", "tc", "egg", "mesh"}
        Neighborhood method (DESIGN.md 4.1-4.4); its parameters go in ``**params``.
    fit : {"implicit", "monge", "nfr"}
        Fit model (DESIGN.md 4.5). ``solver="taubin"|"algebraic"`` selects the implicit solver.
        "nfr" (normal-field regression) regresses PCA normals (``normal_k`` neighbors) on
        position over the neighborhood; it is made for large neighborhoods on noisy data
        (e.g. ``k=384``; docs/research/issue6.md).
    orientation : {"auto", "normals", "viewpoint"}, optional
        How normal signs are fixed; by default "normals" when normals are given, "viewpoint"
        when a viewpoint is given, else "auto".
    normals : array_like, shape (n, 3), optional
        Reference normals (e.g. from the scanner); estimated normals are flipped to agree.
    viewpoint : array_like, shape (3,), optional
        Scanner position; normals are turned to face it.
    faces : array_like, shape (m, 3), optional
        Mesh triangles for ``method="mesh"``; kept in the result.
    workers : int, optional
        Threads to use (default: all cores). Results are identical for any value.
    progress : callable, optional
        ``progress(done, total)`` after each chunk of fitted points. An exception raised by it
        aborts the run (used for cancellation).
    chunk_size : int
        Query points per chunk.
    **params
        Method parameters (e.g. ``k=24`` for knn) and fit parameters (``solver``,
        ``include_self``).

    Returns
    -------
    CurvatureResult

    Raises
    ------
    CurvatureInputError
        Bad cloud (shape, empty, fewer than 10 points, NaN/Inf) or bad normals/faces.
    ParameterError
        Unknown method, fit, orientation or parameter, or a value out of bounds.
    """
    t_start = time.perf_counter()
    if isinstance(points, PointCloud):
        normals = points.normals if normals is None else normals
        faces = points.faces if faces is None else faces
        points = points.points
    pts = as_points(points)
    n = pts.shape[0]
    ref_normals = None if normals is None else as_vectors(normals, n, "normals")
    tri = as_faces(faces, n)
    vp = check_viewpoint(viewpoint)
    mode = resolve_orientation(orientation, ref_normals, vp)
    fit_params, method_params = split_params(params)
    fit_opts = resolve_fit(fit, fit_params)
    nthreads = resolve_workers(workers)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise ParameterError(f"chunk_size must be a whole number >= 1, got {chunk_size!r}")

    # Work on a Z-ordered copy so neighbor reads stay local; every per-point computation is
    # unchanged, and the outputs are put back in input order at the end.
    order = morton_order(pts)
    inv = inverse_permutation(order)
    spts = np.ascontiguousarray(pts[order])
    s_normals = None if ref_normals is None else ref_normals[order]
    s_faces = None if tri is None else inv[tri]
    finder = make_finder(spts, method, faces=s_faces, **method_params)
    res = empty_result(spts, s_faces)
    stage1 = None
    # The first neighbors of each point, kept for the orientation graph (32 bytes a point).
    graph = np.empty((n, ORIENT_K), np.int32) if mode == "auto" else None
    timings = {"neighbors": 0.0, "fit": 0.0, "orientation": 0.0}
    with numba_threads(nthreads):
        if fit == "nfr":
            t0 = time.perf_counter()
            stage1 = stage1_normals(spts, make_finder(spts, "knn", k=fit_opts["normal_k"]),
                                    chunk_size, nthreads)
            timings["stage1_normals"] = time.perf_counter() - t0
        for start in range(0, n, chunk_size):
            stop = min(start + chunk_size, n)
            query = np.arange(start, stop, dtype=np.int64)
            t0 = time.perf_counter()
            nbhd = finder.query(query, workers=nthreads)
            t1 = time.perf_counter()
            out = fit_neighborhoods(spts, query, nbhd, fit, fit_opts["solver"],
                                    fit_opts["include_self"], stage1)
            timings["neighbors"] += t1 - t0
            timings["fit"] += time.perf_counter() - t1
            sl = slice(start, stop)
            res.k1[sl], res.k2[sl], res.residual[sl], res.status[sl] = \
                out.k1, out.k2, out.residual, out.status
            res.normals[sl], res.dir1[sl], res.dir2[sl] = out.normals, out.dir1, out.dir2
            res.neighbor_count[sl] = nbhd.sizes()
            if graph is not None:
                graph[sl] = first_neighbors(nbhd)
            if progress is not None:
                progress(stop, n)
        t0 = time.perf_counter()
        orient(res, mode, s_normals, vp, graph)
        timings["orientation"] = time.perf_counter() - t0
    res = unpermute(res, inv, pts, tri)
    res.mean[:] = 0.5 * (res.k1 + res.k2)
    res.gaussian[:] = res.k1 * res.k2
    timings["total"] = time.perf_counter() - t_start
    res.info = {
        "method": method, "params": dict(finder.params), "fit": fit, **fit_opts,
        "orientation": mode, "workers": nthreads, "points": n,
        "faces": 0 if tri is None else int(tri.shape[0]),
        "status_counts": res.status_counts(), "timings": timings,
    }
    return res


def empty_result(pts: np.ndarray, faces) -> CurvatureResult:
    """A result with every output array allocated (filled by the chunks)."""
    n = pts.shape[0]
    return CurvatureResult(
        points=pts, k1=np.empty(n), k2=np.empty(n), mean=np.empty(n), gaussian=np.empty(n),
        normals=np.empty((n, 3)), dir1=np.empty((n, 3)), dir2=np.empty((n, 3)),
        neighbor_count=np.empty(n, np.int32), status=np.empty(n, np.int8),
        residual=np.empty(n), faces=faces)


def unpermute(res: CurvatureResult, inv: np.ndarray, pts: np.ndarray, faces) -> CurvatureResult:
    """The result of the Z-ordered cloud in input order (``inv`` from inverse_permutation)."""
    fields = {name: arr[inv] for name, arr in res.fields().items()}
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


__all__ = ["FITS", "ORIENTATIONS", "estimate"]
