"""``curvature.estimate``: the one path from points to per-point curvature.

The call is checked (:mod:`~curvature.pipeline.request`), the points put in Z-order
(:mod:`~curvature.pipeline.spatial_order`) and run as one block through an estimator
(:mod:`~curvature.pipeline.block`: plan, neighborhoods, fits), or, for big clouds or with an
executor, as tiles of such blocks with verified halos (:mod:`~curvature.pipeline.tiling`, which
wraps the block and is never imported back); then normals are oriented and the result is put
back in input order with the input's attributes (:mod:`~curvature.pipeline.attributes`).

Work goes through the cloud in chunks of query points so memory stays bounded: only one chunk's
neighborhoods exist at a time, and the outputs are the only per-point arrays kept.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..bounds import diagonal
from ..cloud import PointCloud
from ..errors import ParameterError
from ..estimators.auto import neighbor_rows
from ..estimators.fixed import DEFAULT_CHUNK
from ..fitting import FITS
from ..fitting.uncertainty import add_neighbor_spread
from ..memory import release_freed_memory
from ..neighborhoods.kdtree import build_tree
from ..orientation import (
    ORIENT_K,
    apply_signs,
    signs_auto,
    signs_from_normals,
    signs_from_viewpoint,
)
from ..result import CurvatureResult
from ..uncertainty import NEIGHBOR_SPREAD_WEIGHT, uncertain
from ..validation import as_faces, as_points, as_vectors
from .attributes import carry_input, file_viewpoint, orientation_rule
from .block import DERIVED, compute_block
from .request import (
    DEFAULT_FIT,
    DEFAULT_METHOD,
    METHODS,
    ORIENTATIONS,
    PRESETS,
    check_viewpoint,
    resolve_request,
    resolve_tile_points,
)
from .spatial_order import inverse_permutation, morton_order, take_rows
from .threads import numba_threads
from .tiling import run_tiled

ProgressFn = Callable[[int, int], None]


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
        itself (:mod:`curvature.estimators.auto`; parameters ``k``, ``normal_k``,
        ``noise_threshold``).
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
        halo that is checked to hold everything its points depend on
        (:mod:`curvature.pipeline.tiling`); results are identical to an untiled run. Default:
        tiles of 1M points above 2M points (250k with an ``executor``); 0 never tiles.
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
            own_std = block.own_std
        else:
            res, graph, info, timings, own_std = run_tiled(spts, s_faces, req, tiles,
                                                           progress, executor)
        release_freed_memory()  # what the block's run freed, before orientation's arrays
        t0 = time.perf_counter()
        orient(res, req.mode, s_normals, s_vp, graph)
        timings["orientation"] = time.perf_counter() - t0
        if req.method == "auto":
            t0 = time.perf_counter()
            widen_by_neighbors(res, spts, graph, req.chunk_size, own_std)
            timings["neighbor_spread"] = time.perf_counter() - t0
    # The Z-ordered copies are not needed past orientation (the result's points are replaced
    # by the input's): freed before the fields are reordered, when memory peaks.
    del graph, spts, s_normals, s_vp, own_std
    res.points = None
    release_freed_memory()
    with numba_threads(req.workers):
        res = unpermute(res, inv, pts, tri)
    del inv
    derive_fields(res, diagonal(pts))
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


def unpermute(res: CurvatureResult, inv: np.ndarray, pts: np.ndarray, faces) -> CurvatureResult:
    """The result of the Z-ordered cloud in input order (``inv`` from inverse_permutation).

    Fields are reordered one at a time, so at most one extra field is held at once. Mean and
    Gaussian curvature are derived afterwards, so they are left unfilled here.
    """
    fields = res.fields()
    for name in list(fields):
        if name in DERIVED:
            fields[name] = np.empty(inv.shape[0], fields[name].dtype)
        else:
            fields[name] = take_rows(fields[name], inv)
        setattr(res, name, fields[name])
    return CurvatureResult(points=pts, faces=faces, **fields)


# Points per slice of derive_fields (bounds its temporaries at a few MB).
DERIVE_CHUNK = 1 << 18


def derive_fields(res: CurvatureResult, diagonal: float) -> None:
    """Mean and Gaussian curvature and the ``uncertain`` flag from k1, k2 and their standard
    errors, in place and in slices (no whole-cloud temporaries at the run's memory peak)."""
    n = res.k1.shape[0]
    for start in range(0, n, DERIVE_CHUNK):
        sl = slice(start, min(start + DERIVE_CHUNK, n))
        k1, k2 = res.k1[sl], res.k2[sl]
        np.add(k1, k2, out=res.mean[sl])
        res.mean[sl] *= 0.5
        np.multiply(k1, k2, out=res.gaussian[sl])
        res.uncertain[sl] = uncertain(k1, k2, res.k1_std[sl], res.k2_std[sl],
                                      res.neighbor_count[sl], res.status[sl], diagonal)


def widen_by_neighbors(res: CurvatureResult, points: np.ndarray, graph, chunk_size: int,
                       own_std: np.ndarray | None = None) -> None:
    """Widen the default's standard errors by its neighbors' disagreement, in place
    (:data:`~curvature.uncertainty.NEIGHBOR_SPREAD_WEIGHT`), except at ``own_std`` (n,),
    bool: the sphere and cylinder fits, whose standard errors are their own
    (:data:`~curvature.uncertainty.OWN_STD_SCALE`).

    ``graph`` (n, ORIENT_K), the orientation's neighbor rows where orientation "auto" made
    them, else made here: the same nearest neighbors (each point first) whatever the mode.
    """
    if graph is None:
        graph = np.empty((points.shape[0], ORIENT_K), np.int32)
        neighbor_rows(points, build_tree(points), graph, chunk_size)
    if own_std is None:
        own_std = np.zeros(points.shape[0], bool)
    add_neighbor_spread(res.k1, res.k2, res.normals, graph, NEIGHBOR_SPREAD_WEIGHT,
                        res.k1_std, res.k2_std, res.mean_std, own_std)


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
    # k1 and k2 swap where the normal flips: so do their standard errors
    flip = signs < 0
    res.k1_std[flip], res.k2_std[flip] = res.k2_std[flip], res.k1_std[flip].copy()


__all__ = ["DEFAULT_FIT", "DEFAULT_METHOD", "FITS", "METHODS", "ORIENTATIONS", "PRESETS",
           "estimate"]
