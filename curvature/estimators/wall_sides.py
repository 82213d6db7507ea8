"""Stage-1 normals of thin walls, read over one side of the wall (the default's stage 1).

The stage-1 PCA over ``normal_k`` neighbors reaches through a wall a few neighborhood radii
thick to its other face: on the bench's thin plate (faces 3 to 4 spacings apart, 0.1 % noise)
the faces' PCA normals erred 13 degrees (median; p90 38), a slab's thinnest axis not always
being across it, and the normal fits read that scatter as curvature of faces that are flat.
Such a neighborhood is far from flat (:func:`~curvature.fitting.normal_field.pca_flatness`).
There the PCA is read again over the neighbors the point reaches in short steps from
neighbor to neighbor (:func:`one_sheet_pca`): within one face the points lie about a
spacing apart, while the other face is a wall's thickness away, so the steps stay on the
point's own sheet. The normal is kept where that sheet is flat; on a rim or leading edge a
few spacings in radius (a wall's rounded end) it is not, and the two-sided normal stays
(docs/accuracy.md, section 9, step 15).

Everything here reads the point's own ``normal_k`` neighbors only, so it reaches no farther
than the stage-1 PCA does (tiled runs stay identical to untiled ones).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit, prange

from ..fitting.normal_field import pca_normal_into

__all__ = ["SHEET_NTH", "SHEET_STEP", "SIDE_CANDIDATE", "SIDE_FLAT", "one_sheet_pca",
           "one_side_normals"]

#: A stage-1 neighborhood whose flatness (smallest covariance eigenvalue over the trace) is
#: above this may hold two faces of a wall: a slab reads about 0.1, a noisy plane at 0.1 % noise
#: 0.001, fillets of 6 spacings and corners 0.006 to 0.02, a leading edge of 2.6 spacings 0.03
#: to 0.07. Only these points are read again.
SIDE_CANDIDATE = 0.03
#: The one-sheet neighborhood must be at least this flat for its normal to be kept: faces and
#: the blade's sides 0.001 to 0.003, rims and leading edges 0.02 to 0.13.
SIDE_FLAT = 0.01
#: A step from neighbor to neighbor is at most SHEET_STEP times the distance from the point
#: to its SHEET_NTH-th nearest neighbor (about 1.9 mean spacings on a face): above the
#: distance at which a random sample of a face stays connected (about 1.2), below a wall's
#: thickness of 2.5 to 4. Step 1.0 / 1.2 / 1.5 (`curvature bench parts`' plate and blade,
#: seeds 1 and 2): plate faces 0.191 / 0.229 / 0.338, rims 22.3 / 22.7 / 23.0, blade sides
#: 0.214 / 0.210 / 0.214, leading edge 1.389 / 1.376 / 1.359 (1.09, 20.2, 0.231 and 1.355
#: two-sided). 1.0 reads the plate better but lies nearer the connection distance, which an
#: unevenly sampled scan (stripes, density falling off with range) crosses more often.
SHEET_STEP = 1.2
SHEET_NTH = 8
# Query points per parallel block of one_sheet_pca (its scratch arrays per block).
SHEET_BLOCK = 64


@njit(cache=True, inline="always")
def _dist2(points, a, b):
    """Squared distance between points ``a`` and ``b``."""
    return ((points[a, 0] - points[b, 0]) ** 2 + (points[a, 1] - points[b, 1]) ** 2
            + (points[a, 2] - points[b, 2]) ** 2)


@njit(parallel=True, cache=True)
def one_sheet_pca(points, query, nbr, excluded, out, flat):
    """PCA normals over the neighbors each query point reaches in short steps.

    Starting from the point, a neighbor is reached when it lies within one step of the point
    or of a neighbor reached (single linkage over the list, step :data:`SHEET_STEP` times
    the distance to the :data:`SHEET_NTH`-th nearest neighbor). Where every neighbor is
    reached the normal is the stage-1 one, bit for bit.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    query : ndarray, shape (m,), int64
    nbr : ndarray, shape (m, k), int
        Each query point's nearest neighbors, nearest first (the point itself not listed).
    excluded : ndarray, shape (n,), bool
        Points never reached (outliers).
    out : ndarray, shape (m, 3)
        Output normals (arbitrary sign; NaN where the reached points span no plane).
    flat : ndarray, shape (m,)
        Output flatness of the reached points
        (:func:`~curvature.fitting.normal_field.pca_flatness`).
    """
    m, k = nbr.shape
    nth = min(SHEET_NTH, k) - 1
    blocks = (m + SHEET_BLOCK - 1) // SHEET_BLOCK
    for b in prange(blocks):
        reached = np.empty(k, np.bool_)
        queue = np.empty(k, np.int64)
        kept = np.empty(k, np.int64)
        cov = np.empty((3, 3))
        vec = np.empty((3, 3))
        for j in range(b * SHEET_BLOCK, min(m, (b + 1) * SHEET_BLOCK)):
            p = query[j]
            reach2 = SHEET_STEP * SHEET_STEP * _dist2(points, p, nbr[j, nth])
            for a in range(k):
                reached[a] = False
            # Breadth first from p itself (listed nowhere, so taken as the queue's source).
            tail = 0
            head = -1
            while head < tail:
                src = p if head < 0 else nbr[j, queue[head]]
                head += 1
                for a in range(k):
                    q = nbr[j, a]
                    if not reached[a] and not excluded[q] and _dist2(points, q, src) <= reach2:
                        reached[a] = True
                        queue[tail] = a
                        tail += 1
            # In list order (nearest first), as the stage-1 PCA summed them.
            count = 0
            for a in range(k):
                if reached[a]:
                    kept[count] = nbr[j, a]
                    count += 1
            flat[j] = pca_normal_into(points, p, kept, 0, count, cov, vec, out[j])


def one_side_normals(points: np.ndarray, field: np.ndarray, flat: np.ndarray,
                     radius: np.ndarray, noise: float, excluded: np.ndarray,
                     neighbors: Callable[[np.ndarray, int], np.ndarray],
                     normal_k: int, chunk_size: int) -> np.ndarray:
    """Replace, in place, the stage-1 normals of points on a thin wall by one sheet's PCA.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    field : ndarray, shape (n, 3)
        Stage-1 PCA normals of arbitrary sign (NaN where none); the rows returned are
        overwritten.
    flat : ndarray, shape (n,)
        Flatness of each stage-1 neighborhood
        (:func:`~curvature.fitting.normal_field.pca_flatness`).
    radius : ndarray, shape (n,)
        Distance of each point's farthest stage-1 neighbor.
    noise : float
        The cloud's noise (length unit, standard deviation across the surface).
    excluded : ndarray, shape (n,), bool
        Points neither read again nor counted as neighbors (outliers).
    neighbors : callable
        ``neighbors(rows, k)`` -> (m, k) int array of the ``k`` nearest neighbors of each row
        (the row itself not listed), nearest first.
    normal_k : int
        Neighbors of the stage-1 PCA.
    chunk_size : int
        Rows per neighbor query.

    Returns
    -------
    ndarray, shape (r,), int64
        The rows whose normal was replaced, increasing.
    """
    # A plane's flatness over a disc of radius r with noise s is about s^2 / (r^2 / 2 + s^2):
    # where that alone reaches half of SIDE_FLAT no sheet could pass (a 1M-point plate at
    # 0.1 % noise, 1.5 spacings of it, would read all its points again for none).
    floor = noise * noise / (0.5 * radius * radius + noise * noise)
    rows = np.flatnonzero((flat > SIDE_CANDIDATE) & (floor < 0.5 * SIDE_FLAT)
                          & ~excluded).astype(np.int64)
    if rows.size == 0:
        return rows
    keep = np.zeros(rows.size, bool)
    for start in range(0, rows.size, chunk_size):
        query = rows[start:start + chunk_size]
        out, sheet_flat = np.empty((query.size, 3)), np.empty(query.size)
        one_sheet_pca(points, query, np.ascontiguousarray(neighbors(query, normal_k)),
                      excluded, out, sheet_flat)
        ok = sheet_flat < SIDE_FLAT  # NaN (no plane) compares False
        field[query[ok]] = out[ok]
        keep[start:start + query.size] = ok
    return rows[keep]
