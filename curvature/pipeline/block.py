"""One block of points (a whole cloud, or a tile with its halo) through an estimator: method
"auto" plans and fits by itself, a neighborhood method finds neighborhoods and fits them.
The result is unoriented; orientation and input order come after (:func:`curvature.estimate`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..estimators.auto import AutoRun
from ..estimators.fixed import fit_chunks
from ..neighborhoods import make_finder
from ..orientation import ORIENT_K
from ..result import CurvatureResult
from .request import Request


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
    own_std : ndarray, shape (m,), bool, or None
        Method "auto": the query points whose standard errors are their own fit's, not to be
        widened by the neighbor spread (:func:`curvature.pipeline.widen_by_neighbors`).
    """

    result: CurvatureResult
    graph: np.ndarray | None
    reach: np.ndarray | None
    info: dict
    timings: dict
    own_std: np.ndarray | None = None


def compute_block(spts, s_faces, req: Request, query=None, *, progress=None, plan=None,
                  mesh_graph=None, track_reach: bool = False, dense_stage1=None) -> Block:
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
    dense_stage1 : tuple, optional
        Method "auto" on a dense cloud: the whole cloud's
        :func:`~curvature.estimators.auto.dense_stage1` restricted to the block (block
        indices), so that a tile does not compute it again for its halo. The block then
        makes no orientation graph (the tiled run makes it for the whole cloud), and need
        hold only the thinned points besides ``query``.
    """
    n = spts.shape[0]
    # Every point, in order, unless told otherwise (the default estimator then holds no
    # index array through its run).
    whole = query is None or (len(query) == n and np.array_equal(query, np.arange(n)))
    query = np.asarray(query, np.int64) if query is not None else None
    want_graph = req.mode == "auto" and dense_stage1 is None
    timings: dict = {}
    if req.method == "auto":
        res = empty_result(spts, s_faces)
        graph = np.empty((n, ORIENT_K), np.int32) if want_graph else None
        run = AutoRun(spts, req.auto_params, req.chunk_size, progress, plan=plan,
                      track_reach=track_reach)
        run.run(res, graph, ORIENT_K, None if whole else query, dense_stage1)
        timings.update(run.timings)
        info = {"method": "auto", "params": req.auto_params,
                "fit": "implicit" if run.plan.clean else "nfr", "plan": run.plan.to_dict()}
        reach, own_std = run.reach, run.own_std
        if not whole:
            res = select_rows(res, query, spts[query])
            graph = None if graph is None else graph[query]
            reach = None if reach is None else reach[query]
            own_std = own_std[query]
        return Block(res, graph, reach, info, timings, own_std)
    if query is None:
        query = np.arange(n, dtype=np.int64)
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
    """The result restricted to ``rows``; ``res`` gives up its fields one at a time (at most
    one field is held twice: a tile's rows are most of its working set). The derived fields
    are not filled yet, so they are allocated, not copied."""
    fields = {}
    for name in list(res.fields()):
        arr = getattr(res, name)
        setattr(res, name, None)
        fields[name] = np.empty(rows.shape[0], arr.dtype) if name in DERIVED else arr[rows]
        del arr
    return CurvatureResult(points=points, faces=None, **fields)


# Result fields computed from k1 and k2 (and their errors) at the very end (never written
# before, so their pages cost no memory while a big cloud is computed).
DERIVED = ("mean", "gaussian", "uncertain")


def empty_result(pts: np.ndarray, faces) -> CurvatureResult:
    """A result with every output array allocated (filled by the chunks)."""
    n = pts.shape[0]
    return CurvatureResult(
        points=pts, k1=np.empty(n), k2=np.empty(n), mean=np.empty(n), gaussian=np.empty(n),
        normals=np.empty((n, 3)), dir1=np.empty((n, 3)), dir2=np.empty((n, 3)),
        neighbor_count=np.empty(n, np.int32), status=np.empty(n, np.int8),
        residual=np.empty(n), k1_std=np.empty(n), k2_std=np.empty(n), mean_std=np.empty(n),
        uncertain=np.empty(n, np.uint8), faces=faces)
