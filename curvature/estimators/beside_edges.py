"""Faces beside a rounded thin edge, fitted without the edge (the default's noisy branch).

Where a wall ends in a rounded edge (a blade's leading edge, a plate's rim) the surface turns
by half a turn within a few spacings, and the fits of face points nearby reach onto the edge.
They read its curvature in two ways: their patches hold edge points, and the normals they fit
were bent by the edge (a stage-1 PCA over 48 neighbors that holds edge points tilts towards
it, 4 degrees on the blade below, and the refined normals inherit the tilt). On the
20,000-point blade at 0.1 % noise the side points two to three spacings past the leading
edge's curvature jump read 1.7 on a flat side and carried a sixth of the sides' error.

The edge is known once its circle is (:mod:`~curvature.fitting.rounded_edge`): the points that
read a circle, widened along the surface by :data:`DROP_GROW` times the arc of the circle's
end band (where the faces continue the arc). The points beside it that read no circle,
those within :data:`BESIDE_REACH` times the fit radius of a point that read its own circle
and those the widening covers (the faces past an arc's end), are fitted again from neighbor
lists without the edge, over normals read again by PCA without it wherever it was among a
point's stage-1 neighbors (:func:`one_sided_normals`), and take the new fit. The points of
an arc that read no circle of their own read a neighbor's where they lie on it
(``AutoRun._rounded_edges``), so a point the widening covers and no circle reads lies past
the arc's end, or within noise of it.

Everything here is local: the widening and the reach are per edge point, and the normals are
read again in a tile's halo too, so tiled runs give the results of untiled ones.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

from ..fitting.normal_field import pca_flatness
from ..fitting.rounded_edge import NORMAL_TOLERANCE
from .wall_sides import SIDE_FLAT

__all__ = ["BESIDE_REACH", "DROP_GROW", "beside_rows", "edge_drop", "normals_near",
           "one_sided_normals", "reached", "select_entries", "widening", "without"]

#: The edge left out of the fits: the points that read a circle and every point within this
#: many times the arc of the circle's end band (``NORMAL_TOLERANCE`` degrees times its
#: radius) of one that read its own circle or a thinned share's. Since the points the
#: widening covers are fitted again too, measured with 1 / 1.5 / 2: bench plate's faces,
#: seeds 1-4, 0.199 / 0.198 / 0.188; the 100,000-point blade's sides 0.438 / 0.413 / 0.412
#: (the 20,000-point blade's 0.141 / 0.145 / 0.146, the bench blade's within 1 %). Until
#: then 1 and 1.5 read points at a rim's junction with a face as the face (one read 0
#: instead of 33), which they now do with 2 as well (see the bent wall's test).
DROP_GROW = 2.0
#: Points within this many times an edge point's fit radius (the circle's largest list, 192
#: neighbors) of it are refitted; the default's widest fits reach about twice as far. Bench
#: blade's sides / plate's faces: 0.171 / 0.200 (1), 0.165 / 0.189 (1.5), 0.166 / 0.188 (2),
#: but with 2 the one-sided fits reach the blade's crest (k = 1), which they read 3 % worse
#: than the anchored fits did.
BESIDE_REACH = 1.5


def widening(across: np.ndarray) -> np.ndarray:
    """How far the edge left out reaches past each edge point: :data:`DROP_GROW` times the
    arc of its circle's end band, for curvatures ``across`` (e,) across the edge."""
    return DROP_GROW * np.radians(NORMAL_TOLERANCE) / np.abs(across)


def _within(tree: cKDTree, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Indices (into the tree's points, int64, with repeats) within ``radii`` (c,) of each
    of ``centres`` (c, 3)."""
    hits = tree.query_ball_point(centres, radii, workers=numba.get_num_threads())
    return np.concatenate([np.empty(0, np.int64)] + [np.asarray(h, np.int64) for h in hits])


def edge_drop(tree: cKDTree, points: np.ndarray, edge: np.ndarray,
              across: np.ndarray) -> np.ndarray:
    """The points every fit beside the edge leaves out.

    Parameters
    ----------
    tree : cKDTree
        Over ``points``.
    points : ndarray, shape (n, 3)
    edge : ndarray, shape (e,), int64
        The points that read a circle.
    across : ndarray, shape (e,)
        Their curvature across the edge (1 / the circle's radius).

    Returns
    -------
    drop : ndarray, shape (n,), bool
        ``edge`` and the points within :data:`DROP_GROW` end-band arcs of one.
    """
    drop = np.zeros(points.shape[0], bool)
    drop[edge] = True
    drop[_within(tree, points[edge], widening(across))] = True
    return drop


def normals_near(tree: cKDTree, points: np.ndarray, edge: np.ndarray, across: np.ndarray,
                 drop: np.ndarray, outliers: np.ndarray, r_normal: np.ndarray) -> np.ndarray:
    """The points whose stage-1 normals the edge may have bent, the edge itself and outliers
    left out: those within the widening (:func:`edge_drop`) plus a stage-1 neighborhood's
    radius of an edge point.

    Parameters
    ----------
    tree, points, edge, across
        As for :func:`edge_drop`.
    drop, outliers : ndarray, shape (n,), bool
    r_normal : ndarray, shape (n,)
        Radius of each point's stage-1 neighborhood.

    Returns
    -------
    ndarray, shape (b,), int64, increasing
    """
    near = np.zeros(points.shape[0], bool)
    radius = widening(across) + r_normal[edge]
    near[_within(tree, points[edge], radius)] = True
    return np.flatnonzero(near & ~drop & ~outliers).astype(np.int64)


def beside_rows(tree: cKDTree, points: np.ndarray, rows: np.ndarray, own, drop: np.ndarray,
                skip: np.ndarray) -> np.ndarray:
    """The points of ``rows`` to fit again beside the edge: those left out with it (``drop``:
    the faces past an arc's end) and those within :data:`BESIDE_REACH` times the fit radius
    of a point that read its own circle (``own``), but not those ``skip`` marks (outliers,
    the points that read a circle).

    Parameters
    ----------
    tree : cKDTree
        Over ``points``.
    points : ndarray, shape (n, 3)
    rows : ndarray, shape (m,), int64
        The points whose results are wanted.
    own : tuple or None
        The reads of the points' own circles as ``AutoRun._rounded_edges`` returns them: the
        points first, their fit radius last (None: there are none).
    drop, skip : ndarray, shape (n,), bool

    Returns
    -------
    ndarray, shape (b,), int64, increasing
    """
    near = drop.copy()
    if own is not None:
        near[_within(tree, points[own[0]], BESIDE_REACH * own[-1])] = True
    wanted = np.zeros(points.shape[0], bool)
    wanted[rows] = True
    return np.flatnonzero(near & wanted & ~skip).astype(np.int64)


def without(indptr: np.ndarray, indices: np.ndarray, drop: np.ndarray):
    """CSR neighbor lists without the entries ``drop`` marks; each row keeps its first entry
    (the query point itself).

    Parameters
    ----------
    indptr : ndarray, shape (m + 1,), int64
    indices : ndarray, shape (nnz,)
    drop : ndarray, shape (n,), bool

    Returns
    -------
    indptr, indices : ndarray
        The shorter lists, in the same order.
    """
    keep = ~drop[indices]
    keep[indptr[:-1]] = True
    return select_entries(indptr, indices, keep)


def select_entries(indptr: np.ndarray, indices: np.ndarray, keep: np.ndarray):
    """CSR lists of the entries ``keep`` marks, in the same order.

    Parameters
    ----------
    indptr : ndarray, shape (m + 1,), int64
    indices : ndarray, shape (nnz,)
    keep : ndarray, shape (nnz,), bool

    Returns
    -------
    indptr, indices : ndarray
        The shorter lists (a row may become empty).
    """
    kept = np.zeros(keep.shape[0] + 1, np.int64)
    np.cumsum(keep, out=kept[1:])
    return kept[indptr], indices[keep]


def one_sided_normals(points: np.ndarray, query: np.ndarray, nbr: np.ndarray,
                      drop: np.ndarray, field: np.ndarray) -> np.ndarray:
    """Stage-1 normals again without the edge, in ``field``, where it was among a point's
    neighbors and the rest is flat (:data:`~curvature.estimators.wall_sides.SIDE_FLAT`; a
    thin plate's faces near its rim hold both faces, and keep their normals).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k)
        Each query point's nearest neighbors, itself excluded.
    drop : ndarray, shape (n,), bool
    field : ndarray, shape (n, 3)
        Normals the fits read; rows of ``query`` are replaced.

    Returns
    -------
    ndarray, shape (t,), int64
        The rows replaced.
    """
    left = drop[nbr]
    touched = left.any(axis=1)
    if not touched.any():
        return np.empty(0, np.int64)
    query, nbr, left = query[touched], nbr[touched], left[touched]
    counts = (~left).sum(axis=1)
    indptr = np.zeros(query.shape[0] + 1, np.int64)
    np.cumsum(counts, out=indptr[1:])
    normals = np.empty((query.shape[0], 3))
    flat = np.empty(query.shape[0])
    pca_flatness(points, query, indptr, nbr[~left].astype(np.int64), normals, flat)
    good = np.isfinite(normals).all(axis=1) & (flat <= SIDE_FLAT)
    field[query[good]] = normals[good]
    return query[good].astype(np.int64)


def reached(points: np.ndarray, query: np.ndarray, anchors: np.ndarray, owner: np.ndarray,
            sizes: np.ndarray, own: np.ndarray, own_sizes: np.ndarray, r_normal: np.ndarray,
            normal_k: int, edge: np.ndarray) -> np.ndarray:
    """Whether each query point's fit so far may reach the edge or a normal it bent.

    The fit is its anchor's (``sizes[owner]`` neighbors of ``anchors[owner]``) or, for the
    points of ``own``, the point's own (``own_sizes`` neighbors). Its radius is estimated
    from the stage-1 neighborhood's at its centre, ``r_normal sqrt(size / normal_k)`` (the
    neighbors of a surface patch grow with its area), and the fit reaches the edge where a
    point of ``edge`` lies within it.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (b,), int64
    anchors : ndarray, shape (a,), int64
    owner : ndarray, shape (n,), int64
        Each point's anchor (index into ``anchors``).
    sizes : ndarray, shape (a,)
    own : ndarray, shape (o,), int64
    own_sizes : ndarray, shape (n,)
    r_normal : ndarray, shape (n,)
    normal_k : int
    edge : ndarray, shape (d,), int64
        The points left out and those whose normals were read again.

    Returns
    -------
    ndarray, shape (b,), bool
    """
    mine = np.isin(query, own)
    centre = np.where(mine, query, anchors[owner[query]])
    size = np.where(mine, own_sizes[query], sizes[owner[query]])
    radius = r_normal[centre] * np.sqrt(np.maximum(size, normal_k) / normal_k)
    d, _ = cKDTree(points[edge]).query(points[centre])
    return d <= radius
