"""The default's wedge-tip pass: a thin wall's sharp rounded edge read from its faces.

After the umbilic pass, the points whose stage-1 neighborhoods are far from flat (the rounded
edges' candidates) are tried for the tip of a thin wedge (:mod:`curvature.fitting.wedge_tip`).
A usable fit replaces a point's estimate where that reads the edge flatter than the fit by
more than :data:`DISAGREE` of the fit's standard errors (a face beside the tip: where it
reads the face more curved by as much) (the bench's blade's trailing
edge, k = 100 at 0.7 spacings, read 0 to 1.4 before; docs/accuracy.md section 9, step 33).
A wall whose faces run parallel is read the same way at its rounded end (the bench's thin
plate's rims, step 36). A point the arc reads takes the fit also where its standard error is
below the estimate's (step 39: the plate's rims at 0.1 % 1.22 -> 0.95 on the bench).
"""

from __future__ import annotations

import numpy as np

from ..fitting.wedge_tip import WEDGE_K, wedge_tip_fits
from ..uncertainty import with_floor

__all__ = ["DISAGREE", "wedge_tip_pass"]

#: A fit replaces an estimate whose largest |curvature| lies more than this many of the fit's
#: standard errors below the fit's curvature (the estimate's own may be large: 58 to 99 at
#: some of the blade's tip points, which read 0).
DISAGREE = 2.0


def wedge_tip_pass(points, query_nearest, res, rows, noise: float, largest: int,
                   outliers: np.ndarray, candidates: np.ndarray, chunk: int, reach=None,
                   floor_scale: float = 0.0, own_std=None) -> int:
    """Replace the estimates of ``rows`` at the tips of thin wedges, in place.

    Parameters
    ----------
    points, query_nearest, res, rows, outliers, chunk, reach, floor_scale, own_std
        As for :func:`~curvature.estimators.umbilic_pass.umbilic_pass`.
    noise : float
        The cloud's noise (length unit); nothing is done where it is not finite or zero.
    largest : int
        Most neighbors a fit may use.
    candidates : ndarray, shape (c,), int64
        The points that may lie on a rounded edge.

    Returns
    -------
    int
        How many estimates were replaced.
    """
    n = points.shape[0]
    k = min(WEDGE_K, largest, n - 1)
    if not (np.isfinite(noise) and noise > 0.0) or k < 64:
        return 0
    query_rows = np.intersect1d(rows, candidates).astype(np.int64)
    replaced = 0
    for start in range(0, query_rows.shape[0], chunk):
        query = query_rows[start:start + chunk]
        nbr, d2 = query_nearest(query, k)
        nbr = np.where(outliers[nbr], -1, nbr)
        out = np.empty((query.shape[0], 12))
        wedge_tip_fits(points, query, nbr, noise, out)
        if reach is not None:
            reach[query] = np.fmax(reach[query], np.sqrt(d2[:, -1]))
        ok = np.isfinite(out[:, 0])
        at, out = query[ok], out[ok]
        current = np.fmax(np.abs(res.k1[at]), np.abs(res.k2[at]))
        face = out[:, 11] == 1.0
        flatter = np.where(face, current > np.abs(out[:, 0]) + DISAGREE * out[:, 1],
                           current < out[:, 0] - DISAGREE * out[:, 1])
        # an arc read whose standard error is below the estimate's replaces it too
        flatter |= ~face & (out[:, 1] < np.fmax(res.k1_std[at], res.k2_std[at]))
        flatter &= res.status[at] == 0
        _store(res, at[flatter], out[flatter], k, floor_scale)
        if own_std is not None:
            own_std[at[flatter]] = True
        replaced += int(flatter.sum())
    return replaced


def _store(res, at, out, count: int, floor_scale: float) -> None:
    """Write the wedge fits ``out`` (shape (r, 12), as
    :func:`~curvature.fitting.wedge_tip.wedge_tip_fits` returns them) at ``at`` into
    ``res``: the fit's outward normal, its curvature across the edge and the estimate's
    normal curvature along the edge's axis, ordered k1 >= k2 with their directions."""
    if at.size == 0:
        return
    k, se = out[:, 0], out[:, 1]
    normal, across, axis = out[:, 2:5], out[:, 5:8], out[:, 8:11]
    # the estimate's normal curvature along the axis (a smooth direction it reads well),
    # signed for the fit's outward normal (the normals' signs are fixed later, by orientation)
    sign = np.where(np.sum(res.normals[at] * normal, axis=1) < 0.0, -1.0, 1.0)
    c1 = np.sum(res.dir1[at] * axis, axis=1)
    c2 = np.sum(res.dir2[at] * axis, axis=1)
    k_axis = sign * np.nan_to_num(res.k1[at] * c1 * c1 + res.k2[at] * c2 * c2)
    s_axis = np.nan_to_num(np.fmax(res.k1_std[at], res.k2_std[at]))
    first = k >= k_axis
    # right-handed (dir1, dir2, normal) either way
    along = np.cross(normal, across)
    res.k1[at] = np.where(first, k, k_axis)
    res.k2[at] = np.where(first, k_axis, k)
    res.dir1[at] = np.where(first[:, None], across, along)
    res.dir2[at] = np.where(first[:, None], along, -across)
    res.normals[at] = normal
    std_across = with_floor(se, k, k, floor_scale)
    res.k1_std[at] = np.where(first, std_across, s_axis)
    res.k2_std[at] = np.where(first, s_axis, std_across)
    res.mean_std[at] = 0.5 * np.hypot(std_across, s_axis)
    res.neighbor_count[at] = count
