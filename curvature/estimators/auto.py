"""The default estimator (``method="auto"``): picks its model and scale from the cloud itself.

On noisy scans the neighborhood size decides the error far more than the fit model
(docs/accuracy.md), and users cannot tune it per scan. This estimator measures the cloud first:

1. **Plan** (:func:`plan_auto`): on a geometric subsample it measures the point spacing (median
   distance to the 24th neighbor) and the noise (median RMS residual of quadratic Monge fits
   over 24 neighbors), relative to that spacing.
2. **Clean clouds** (relative residual of cubic fits over 24 neighbors below
   ``noise_threshold``, :func:`cubic_noise`): the paper's implicit quadric over
   24 neighbors, which is exact on quadrics and within a few 0.1 % elsewhere.
3. **Noisy clouds**: normal fits over ``k`` neighbors, which average noise away. Stage-1 PCA
   normals (``normal_k`` neighbors) are fitted around *anchors*, one point per grid cell of 1.5
   spacings, by two models (:func:`~curvature.fitting.normal_field.nfr_anchor_fits`): the
   normal-constrained quadric (normals along the gradient of a quadric; exact on every quadric
   at any size, 9 unknowns) and, where it fits the normals clearly better (misfit below
   ``nfr_ratio`` times the quadric's), the cubic normal field (20 unknowns; follows surfaces that
   are no quadric at this scale, such as a torus's inner side). Every point reads its curvature
   off its cell anchor's model at its own position. A second pass, same size, fits the normals
   of the first, refined once more away from features (:meth:`AutoRun._refine_again`).
   The first reads the normals at the cloud's border at their PCA
   neighborhoods' centroids, where such a normal belongs, as the normals of quadratic height
   fits there (:mod:`curvature.fitting.border_shift`); on a wall a few spacings thick the
   stage-1 PCA is read over one side of it (:mod:`.wall_sides`). Anchors cut the work of the
   large fits about thirteenfold at no measured loss of accuracy; the second pass lowers the
   error further (torus at 0.5 % noise: 0.035 -> 0.026).
   On clouds of fewer than ``k / max_share`` points ``k`` is lowered (:meth:`AutoRun.fit_k`).
4. **Scale per anchor** (:mod:`curvature.fitting.scale_selection`): beside the fit over ``k``
   neighbors, each anchor fits nested prefixes of its neighbor list (Monge quadrics over 24 and
   48 positions, normal-constrained quadrics over 96 and 192) and keeps the largest fit whose
   curvature agrees with every smaller one within ``scale_gamma`` standard errors. Flat faces
   keep large fits, fillets, corners and leading edges small ones (pass 2; pass 1, which only
   refines normals, uses the normal-fit rungs). Points in a cell whose anchor, or a nearby
   one, kept at most 192 neighbors fit the same ladder around themselves instead of reading
   the anchor's model (:meth:`AutoRun._refit`): a small patch read a cell diagonal off its
   centre straddles the feature's edge. ``neighbor_count`` reports the kept size.
5. **Guards**: a fit whose curvature radius is below half the spread of its points
   (``|k| h > 2``) is not admitted and points fall back to their anchor's own reading, so a
   plane never reads 10^5; points far off their neighbors' surface (outliers,
   :mod:`curvature.fitting.outliers`) are left out of every fit and never anchor a cell. On
   clean clouds the implicit quadric over 24 neighbors is replaced by one over 16 or 12 where it
   straddles a curvature jump (its residual far above the smaller fits'), and a fit with
   ``|k| h > 1``, or one the height quadric over its points does not confirm
   (:mod:`curvature.fitting.height_check`), goes to the anchored fits.
6. **Features the fits cannot resolve**, both branches at the end: sphere and cylinder fits
   where the points prefer them (noisy clouds, :mod:`.umbilic_pass`), and the tips of thin
   wedges and the rounded ends of walls, whose radius the faces fix, and the faces beside
   them (:mod:`.wedge_tip_pass`).

Everything depends on the points' coordinates only, never on their order, so the results are
identical for any point order and any ``workers``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace

import numba
import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from ..bounds import bounding_box, diagonal
from ..fitting import scale_selection
from ..fitting.border_shift import border_offsets, centroid_normals
from ..fitting.height_check import unconfirmed
from ..fitting.kernels import FIT_IMPLICIT, FIT_MONGE, SOLVER_TAUBIN, fit_batch
from ..fitting.normal_field import (
    MODEL_QUADRIC,
    N_TERMS,
    nfr_from_anchors,
    pca_flatness,
    pca_normals,
)
from ..fitting.normal_quadric import N_QUAD
from ..fitting.outliers import (
    FACE_K,
    ISOLATION_K,
    OWN_SHEET_CANDIDATE,
    OWN_SHEET_K,
    between_faces,
    isolated,
    off_sheets,
    off_surface,
    sheet_limit,
)
from ..fitting.parallel_sheets import SHEET_K, own_sheet_lists, parallel_sheets
from ..fitting.rounded_edge import (
    EDGE_FAN_K,
    EDGE_KEEP,
    EDGE_LADDER,
    EDGE_NORMAL_K,
    FAN_MIN,
    edge_circle_fits,
    read_edge_circles,
    worth_trying,
    wraps,
)
from ..fitting.scale_selection import (
    DEFAULT_GAMMA,
    RIDGE_POOL,
    TURN_MONGE_K,
    multiscale_anchor_fits,
)
from ..fitting.shifted import adopt_neighbor_fits
from ..memory import release_freed_memory
from ..neighborhoods.kdtree import build_tree, knn_parallel
from ..params import ParamSpec
from ..status import Status
from ..uncertainty import (
    ANCHORED_MEAN_SHARE,
    CLEAN_CALIBRATION,
    NOISE_RESIDUAL_SHARE,
    REFINED_AGAIN_SIGMA,
    anchored_std,
    with_floor,
)
from .beside_edges import (
    BESIDE_REACH,
    beside_rows,
    edge_drop,
    normals_near,
    one_sided_normals,
    reached,
    select_entries,
    widening,
    without,
)
from .sampling import cell_ijk, grid_keys, thinned
from .umbilic_pass import umbilic_pass
from .wall_sides import one_side_normals
from .wedge_tip_pass import wedge_tip_pass

# Neighbors of the spacing and noise measurements and of the clean-cloud fit.
PLAN_K = 24
AUTO_PARAMS = (
    # k is the largest neighborhood; its floor is the smallest fit auto makes anyway (the
    # clean-cloud fit and the first scale rung), so every k it accepts up to 768 is honoured
    # as given (up to 1152 on quieter clouds, above on clouds noisier than wide_noise).
    ParamSpec("k", int, 1536, PLAN_K, 4096,
              help="largest neighborhood of the curvature fits on noisy clouds, both passes: "
                   "the fits over 24, 48, 96, 192, 384 and 768 neighbors below k compete with "
                   "the one over k (scale_gamma); fits above 384 use every (size // 384)-th "
                   "neighbor; at least 24, the clean-cloud fit's size; at most 1152 on clouds "
                   "whose relative noise is below wide_noise, and above 768 there only where "
                   "the fit's patch centres on its point; lowered on small clouds "
                   "(max_share)"),
    ParamSpec("normal_k", int, 48, 12, 256, help="neighbors of the stage-1 PCA normals"),
    ParamSpec("max_share", float, 0.04, 0.0, 1.0,
              help="share of the cloud's points that bounds the fits on small clouds: k is "
                   "lowered to at most twice max(48, max_share * points) (four times above 768 "
                   "neighbors on clouds of 9,600 points and more), and a fit over "
                   "max(48, max_share * points) neighbors is among the candidates"),
    ParamSpec("nfr_ratio", float, 0.7, 0.0, 1e6,
              help="the cubic normal field replaces the normal-constrained quadric at an anchor "
                   "where its normal misfit is below this fraction of the quadric's (0: quadric "
                   "everywhere; large: field everywhere)"),
    ParamSpec("scale_gamma", float, DEFAULT_GAMMA, 0.0, 100.0,
              help="per-anchor neighborhood size on noisy clouds: of the fits over 24, 48, 96, "
                   "192 and k neighbors, the largest whose curvature agrees with every smaller "
                   "one within this many standard errors (0: every anchor uses k)"),
    ParamSpec("dense_noise", float, 0.45, 0.0, 1e6,
              help="relative noise above which the fits see the means of grid cells of the "
                   "cloud instead of its points, so a denser scan covers a larger patch with "
                   "the same neighbors (large: never)"),
    ParamSpec("wide_noise", float, 0.05, 0.0, 1e6,
              help="relative noise below which the fits stop at 1152 neighbors whatever k, "
                   "and go beyond 768 only where the patch centres on its point: above it k "
                   "is honoured, up to 4 times max_share of clouds of 9,600 points and more "
                   "(0: k everywhere; dense clouds, whose fits see a thinned share, stop at "
                   "768)"),
    ParamSpec("noise_threshold", float, 0.001, 0.0, 1.0,
              help="relative noise (RMS residual of cubic fits over 24 neighbors / spacing) "
                   "below which a cloud counts as clean and gets the implicit quadric over 24 "
                   "neighbors"),
)
# The plan's subsample keeps one point per cell of this fraction of the bounding-box diagonal.
PLAN_CELLS = 64
# Anchor grid cell, in spacings (about 13 points a cell on a surface).
ANCHOR_CELL = 1.5
# Points whose anchor, or an anchor within REFIT_ZONE cells of it, kept a fit over at most
# REFIT_BELOW neighbors get fits of their own over at most REFIT_SIZE (AutoRun._refit). The
# zone (filleted box at 0.05 % noise: corners 0.61 -> 0.45 with 1.1 cells, mean of the larger
# of the k1 and k2 errors) catches the corner and fillet points whose own anchor sits just
# outside the feature and kept a wide fit. Refitting beside 192-point fits too (not only 96
# and below) gains up to 20 % on a noisy torus (10,000 points at 0.25 %: 0.0197 -> 0.0163) at
# 15 % of a 1M-point torus at 0.1 % refitted (1.3x the time).
REFIT_BELOW = 192
REFIT_SIZE = 192
REFIT_ZONE = 1.1
# The first pass's normals are refined once more by a pass like it over them
# (AutoRun._refine_again), at the anchors farther than REFINE_AGAIN_ZONE cells from every
# anchor whose first-pass fit kept fewer than REFINE_AGAIN_FROM neighbors. On smooth surfaces
# the second pass then fits normals with less noise (10,000 points, seeds 1 and 2, ratio to
# the best CGAL jet: Bezier patch 0.53-0.66 -> 0.49-0.57, sphere and cylinder up to a third
# less). Near a fillet, a corner or a rim a fit of normals that one pass already smoothed
# spreads the feature further onto its faces (refined everywhere: a filleted box's faces at
# 0.1 % +15 %, a blade's crest +32 %), and the first pass keeps smaller fits there. At 0.5 %
# noise fits below 192 no longer mark the features: refined again beyond 4 cells of those,
# the box's median k1 error went 0.61 -> 0.84 and a filleted cylinder's k2 0.078 -> 0.126;
# beyond 4 cells of those below 384, 0.61 and 0.077 (3 cells: 0.093, 2: 0.116), while the
# part figures at 0.05-0.1 % stay within 1 % (docs/accuracy.md section 8).
REFINE_AGAIN_FROM = 384
REFINE_AGAIN_ZONE = 4.0
# The thinned share of a dense cloud selects its scales with this many times scale_gamma: its
# points lie within noise of about a fifth of their spacing, where chance disagreements of the
# small fits are common, and its anchors' models are read by every point of the cloud around
# them, with no refits. 1M points at 0.25 % noise, mean |k1| error: Bezier 0.131 with 3.5,
# 0.024 with 5; torus 0.027 and 0.020.
DENSE_GAMMA_SCALE = 5.0 / 3.5
# Fewest neighbors max_share lowers k to.
SHARE_MIN_K = 48
# The largest fit covers at most this many times max_share of the cloud.
SHARE_TOPS = 2
# Below wide_noise the fits stop at QUIET_K neighbors; above it k (default 1536) is honoured,
# covering at most WIDE_SHARE_TOPS times max_share of clouds of WIDE_MIN_POINTS and more
# (1536 is 16 % of 9,600 points): the bias of a wider fit is below the noise of the narrower
# ones there, and Lepski's rule turns it down at features. 10,000 points, seeds 1 and 2, ratio
# to the best CGAL jet (docs/accuracy.md section 8): Bezier patch at 0.2 to 0.5 % 0.51-0.57 ->
# 0.45-0.50, sphere and cylinder 31 to 55 % less error, ellipsoid up to 11 % less, torus
# unchanged. At 0.1 % (relative noise 0.03-0.04; the part shapes at 0.05-0.1 % read
# 0.008-0.039) the 1536 top's bias hides below its interval but not below its error: the
# Bezier patch's band within 0.05-0.1 of its border (one-sided patches) 0.017 -> 0.024.
# Quieter clouds stop at QUIET_K, where a top wider than BASE_K is fitted only at anchors
# its patch centres on (QUIET_SIDE, scale_selection._off_centre: the centroid of its points
# within 0.09 of their RMS distance from the anchor): by a border, or where the surface bends
# away within the patch, its bias is not turned down by Lepski's rule (stop 40: Bezier patch
# at 0.1 %, seeds 1 to 3, 0.54 -> 0.50 per axis, 0.50 -> 0.47 with view noise; a 1024 top
# without the limit, seeds 1 and 2: 0.52 and 0.52). Dense clouds' thinned shares stop at
# BASE_K.
BASE_K = 768
QUIET_K = 1152
QUIET_SIDE = 0.09
WIDE_SHARE_TOPS = 4
WIDE_MIN_POINTS = 9600
# Clean clouds: smaller implicit fits tried where the 24-neighbor one is not exact, the
# residual (relative to spacing) below which a fit counts as exact, and how much larger than
# the smallest residual the kept (largest) fit's may be.
CLEAN_SIZES = (16, 12)
CLEAN_EXACT = 1e-9
CLEAN_RESIDUAL_RATIO = 50.0
# The support limit of clean fits (|k| h, h their RMS neighbor distance), tighter than the
# noisy fits' SUPPORT: a leading edge of 3.5 spacings reads 0.53 over 24 neighbors, while the
# implicit quadrics that straddle a fillet's edge read 1.5 and more.
CLEAN_SUPPORT = 1.0
# A point adopts a neighbor's far better fit (curvature.fitting.shifted) only if it lies on
# that fit's quadric within this many spacings.
CLEAN_ON_SURFACE = 1e-7
# The wedge-tip fits' noise on clean clouds (spacings): their tolerance for the profile's
# lines and arc. Noise-free, the bench's blade's trailing edge (k = 100, 0.7 spacings) read
# 100.0 to 100.6 (p10 to p90) at all its 91 points with 0.07; with 0.007, 50 of them.
CLEAN_WEDGE_NOISE = 0.05
# Dense noisy clouds (relative wide noise above ``dense_noise``) are fitted on a random share
# of their points with relative wide noise DENSE_TARGET, whose normals come from the whole
# cloud: there a fixed neighbor count covers the patch it covers on a cloud of the right
# density, and the normals average more points than that cloud has.
DENSE_TARGET = 0.2
# Thinned shares of the cloud on which rounded edges are looked for too, each where it keeps
# at least COARSE_MIN_POINTS points (AutoRun._coarse_edge_reads): the leading edge of a
# 100,000-point blade spans 8 spacings' radius, twice the circles' reach at full density.
COARSE_SHARES = (0.25, 0.0625)
COARSE_MIN_POINTS = 8000
# ... and only their circles of this many plan spacings' radius and more (those at full
# density read up to about 1.3: the 20,000-point blade's leading edge; the 100,000-point one's
# is 2.9; the wedge beside its trailing edge, at the quarter share, up to 1.6). 2.0 until stop
# 47: at 40,000 to 50,000 points the leading edge is 1.9 to 2.1 and its circles read either
# side of 2.0, so part of the arc read none and was fitted as a face (k1 2 to 5 for 20): the
# leading edge read 0.52 to 5.9 (seeds 1 to 3; over 1.3 on 7 of the 9), 0.36 to 0.64 with 1.8.
COARSE_MIN_RADIUS = 1.8
# The points of a rounded edge that read no circle of their own (its candidates and fan test
# miss some, its fit fails at others) read the nearest circle fitted at full density where
# they lie on its arc, within this share of that circle's list radius: on the 20,000-point
# blade (seed 1) 69 of the leading edge's 384 points read none, and erred 1.55 against 0.22.
# With 0.25 one is left; 0.5 and 1 read every one alike.
FILL_REACH = 0.5
# ... of circles with at least this many points that read their own circle (themselves
# included) within that reach: an isolated circle is a misfit more often than an edge. Across
# the 20,000-point blade's trailing edge (radius 0.7 spacings, k = 100) 5 to 7 own circles
# read 38 to 63; read by all their neighbors, they put 29 side points within 2 spacings of
# that edge at 38 to 61 (seed 2; 11 with 3). The blade's edge zone without that edge's tip,
# mean error of seeds 2 / 3: 2.34 / 1.95 (1), 1.56 / 1.95 (2), 1.56 / 1.29 (3).
FILL_CONFIRM = 3
# A point reads the first of its this many nearest circles (filled and thinned shares' reads)
# on whose arc it lies: the nearest alone left points of the arcs' end bands unread, which
# the edge's widening then fitted as faces (the 400,000-point blade's leading edge 0.637;
# 0.621 / 0.588 / 0.559 with 2 / 4 / 8). The bench's plate's edge zone (seeds 1-4) 4.10 ->
# 3.87 / 3.57 / 3.52; the bent wall's faces near the rims 0.75 -> 0.80 / 0.81 / 0.87, where
# more points at a rim's junction with a face read the rim.
READ_CIRCLES = 4
# Fits whose RMS distance to their points exceeds this many noise standard deviations are
# tested for two parallel sheets (AutoRun._sheets): the thin plate's over both faces read 4 to
# 9 at 0.05 to 0.25 % noise (2.3 at 0.5 %, where the faces' parallel test decides nothing).
SHEET_DISTANCE = 2.0
# Neighbors looked at beyond normal_k when the outliers are left out of a stage-1 normal.
RENORMAL_EXTRA = 16
#: Rounds of the outlier test again at the points whose neighbors lost an outlier (each
#: round at the neighbors of the points the last one flagged).
UNMASK_ROUNDS = 2
# Neighbors of the wide noise measurement (AutoPlan.wide_noise).
DENSE_K = 192
# Largest ratio of the wide to the 24-neighbor relative noise of a dense cloud.
DENSE_CONSISTENT = 4.0
# Most neighbors of the thinned cloud's stage-1 normals.
DENSE_NORMAL_K = 1024


@dataclass(frozen=True)
class AutoPlan:
    """Cloud-wide quantities every part of a run must share (also across tiles).

    Attributes
    ----------
    spacing : float
        Median distance of a point to its 24th nearest neighbor.
    noise : float
        Relative noise: median RMS residual of 24-neighbor Monge fits divided by ``spacing``.
    clean : bool
        ``cubic_noise < noise_threshold``: the implicit quadric is used.
    origin : tuple of float
        Corner of the anchor grid (the cloud's bounding-box minimum).
    cell : float
        Anchor grid cell size.
    points : int
        Points of the whole cloud (``max_share`` is a share of them).
    wide_noise : float
        Relative noise measured over :data:`DENSE_K` neighbors, against the spacing their
        patch's area gives (NaN on clean clouds): unlike ``noise`` it does not saturate where
        the noise exceeds the spacing.
    dense_share : float
        Share of the points the fits see (1: all; :class:`AutoRun` ``_dense``).
    dense : AutoPlan or None
        The plan of that thinned cloud.
    cubic_noise : float
        As ``noise``, from cubic height fits (:func:`cubic_noise`): what the quadratic fits
        leave of a smooth surface's shape (a coarse torus: 0.004) mostly goes, noise stays.
    """

    spacing: float
    noise: float
    clean: bool
    origin: tuple
    cell: float
    points: int
    wide_noise: float = np.nan
    dense_share: float = 1.0
    dense: AutoPlan | None = None
    cubic_noise: float = np.nan

    def to_dict(self) -> dict:
        return asdict(self)


@njit(cache=True)
def _cell_representatives(points, cells, cell_of, origin, cell, avoid):
    """Per cell, the point nearest the cell's centre (ties: smaller x, then y, then z), among
    the points not in ``avoid`` where the cell has any.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    cells : int
        Number of distinct cells.
    cell_of : ndarray, shape (n,), int64
        Cell of every point, in ``range(cells)``.
    origin : ndarray, shape (3,)
    cell : float
        Grid corner and cell size (each point's cell centre is recomputed from them).
    avoid : ndarray, shape (n,), bool
        Points that represent a cell only when it has no other.

    Returns
    -------
    ndarray, shape (cells,), int64
        The representative point of every cell.
    """
    best = np.full(cells, -1, np.int64)
    best_d = np.empty(cells)
    for i in range(points.shape[0]):
        c = cell_of[i]
        d = 0.0
        for t in range(3):
            center = origin[t] + (cell_ijk(points[i, t], origin, cell, t) + 0.5) * cell
            d += (points[i, t] - center) ** 2
        b = best[c]
        if b >= 0 and avoid[i] != avoid[b]:
            if avoid[i]:
                continue
            best[c] = i
            best_d[c] = d
            continue
        if b < 0 or d < best_d[c] or (d == best_d[c] and (
                points[i, 0], points[i, 1], points[i, 2]) < (points[b, 0], points[b, 1],
                                                             points[b, 2])):
            best[c] = i
            best_d[c] = d
    return best


def grid_cells(points: np.ndarray, origin: np.ndarray, cell: float,
               avoid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Representatives of the occupied cells of a grid, and each point's cell.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    origin : ndarray, shape (3,)
        Grid corner.
    cell : float
        Cell size.
    avoid : ndarray, shape (n,), bool, optional
        Points that represent a cell only when it has no other (outliers).

    Returns
    -------
    reps : ndarray, shape (c,), int64
        One point per occupied cell (the nearest to its centre), increasing.
    owner : ndarray, shape (n,), int64
        Index into ``reps`` of every point's cell representative.
    """
    origin = np.asarray(origin, np.float64)
    # Keys in one pass (no (n, 3) temporaries: this runs on whole 10M-point clouds).
    ukeys, cell_of = np.unique(grid_keys(points, origin, float(cell)), return_inverse=True)
    cell_of = cell_of.ravel()
    if avoid is None:
        avoid = np.zeros(points.shape[0], np.bool_)
    best = _cell_representatives(points, ukeys.shape[0], cell_of, origin, float(cell), avoid)
    del ukeys
    order = np.argsort(best)
    reps = best[order]
    rank = np.empty_like(order)
    rank[order] = np.arange(order.shape[0])
    return reps, rank[cell_of]


def coarse_cell(points: np.ndarray, cells: int) -> float:
    """A grid cell that cuts the bounding-box diagonal into ``cells`` (never zero)."""
    diag = diagonal(points)
    return diag / cells if diag > 0.0 else 1.0


def knn_csr(points: np.ndarray, tree: tuple, idx: np.ndarray, k: int):
    """k nearest neighbors of ``points[idx]`` as CSR arrays plus squared distances.

    Returns
    -------
    indptr : ndarray, shape (m + 1,), int64
    indices : ndarray, shape (m * k,), int32
    d2 : ndarray, shape (m, k)
    """
    m = idx.shape[0]
    nbr = np.empty((m, k), np.int32)
    d2 = np.empty((m, k))
    knn_parallel(points, tree, idx, k, nbr, d2)
    return np.arange(0, (m + 1) * k, k, dtype=np.int64), nbr.ravel(), d2


#: Residuals beyond this many robust standard deviations are left out of the noise's cubic
#: fits (a thin wall's other face within a point's 24 nearest; :func:`cubic_noise`).
TRIM_SIGMA = 4.0
TRIM_ROUNDS = 2


def cubic_noise(points: np.ndarray, sample: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """RMS residual of a cubic height function over each sample's neighbors.

    The quadratic Monge residual of the plan counts a smooth surface's cubic terms as noise:
    on a coarse noise-free torus or ellipsoid it reads 0.003 to 0.004 spacings, more than
    noise of 0.005 % of the diagonal gives, so the two cannot be told apart by it. The cubic
    fit (10 terms over the 25 points, in the points' PCA frame) follows those terms; its
    residual is the noise (times about 0.9) plus what is left of the shape, one order smaller.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    sample : ndarray, shape (m,), int
    nbr : ndarray, shape (m, k), int
        ``k`` >= 11 nearest neighbors of each sample point.

    Returns
    -------
    ndarray, shape (m,)
        In the points' length unit (NaN where the fit is degenerate).
    """
    rms = np.full(sample.shape[0], np.nan)
    with np.errstate(all="ignore"):
        local = points[np.concatenate([sample[:, None], nbr], axis=1)]
        local = local - local.mean(axis=1, keepdims=True)
        # Each neighborhood in units of its own size, so any coordinate range stays finite;
        # one that overflows or has no extent gives NaN.
        size = np.sqrt(np.mean(np.sum(local * local, axis=2), axis=1))
        rows = np.flatnonzero(np.isfinite(size) & (size > 0))
        local = local[rows] / size[rows, None, None]
        try:
            _, axes = np.linalg.eigh(np.einsum("mki,mkj->mij", local, local))
        except np.linalg.LinAlgError:
            return rms
        frame = np.einsum("mki,mij->mkj", local, axes)  # column 0: along the normal
        height, u, v = frame[..., 0], frame[..., 1], frame[..., 2]
        radius = np.sqrt(np.mean(u * u + v * v, axis=1, keepdims=True))
        radius[~(radius > 0)] = 1.0
        u, v = u / radius, v / radius
        design = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v, u ** 3, u * u * v,
                           u * v * v, v ** 3], axis=-1)
        gram = np.einsum("mki,mkj->mij", design, design)
        rhs = np.einsum("mki,mk->mi", design, height)
        solvable = np.isfinite(gram).all(axis=(1, 2))
        if solvable.any():
            solvable[solvable] = np.linalg.cond(gram[solvable]) < 1e12
        if solvable.any():
            design, height = design[solvable], height[solvable]
            coef = np.linalg.solve(gram[solvable], rhs[solvable][..., None])[..., 0]
            keep = np.ones(height.shape, bool)
            for _ in range(TRIM_ROUNDS):
                resid = height - np.einsum("mki,mi->mk", design, coef)
                # (1.4826 median |r|: the standard deviation of Gaussian residuals)
                scale = 1.4826 * np.median(np.abs(np.where(keep, resid, np.nan)), axis=1)
                keep = np.abs(resid) <= TRIM_SIGMA * scale[:, None]
                refit = (~keep).any(axis=1) & (keep.sum(axis=1) > design.shape[-1] + 2)
                if not refit.any():
                    break
                keep[~refit] = True
                w = design[refit] * keep[refit][..., None]
                g = np.einsum("mki,mkj->mij", w, design[refit])
                ok = np.linalg.cond(g) < 1e12
                sub = np.flatnonzero(refit)[ok]
                keep[np.flatnonzero(refit)[~ok]] = True
                coef[sub] = np.linalg.solve(
                    g[ok], np.einsum("mki,mk->mi", w[ok], height[sub])[..., None])[..., 0]
            resid = np.where(keep, height - np.einsum("mki,mi->mk", design, coef), 0.0)
            dof = np.maximum(keep.sum(axis=1) - design.shape[-1], 1)
            rms[rows[solvable]] = (np.sqrt(np.sum(resid * resid, axis=1) / dof)
                                   * size[rows[solvable]])
    return rms


def _relative_median(residuals: np.ndarray, spacing: float) -> float:
    """Median of the finite ``residuals`` over ``spacing``; inf when there is none."""
    finite = residuals[np.isfinite(residuals)]
    return float(np.median(finite)) / spacing if finite.size and spacing > 0 else np.inf


def plan_sample(points: np.ndarray) -> np.ndarray:
    """The plan's geometric subsample: one point per cell of :data:`PLAN_CELLS` across the
    bounding-box diagonal, shape (s,), int64, increasing (:func:`grid_cells`' representatives,
    found on a dense array of the few coarse cells instead of a sort of every point's key)."""
    # (a cell of 1/PLAN_CELLS of the diagonal: at most PLAN_CELLS + 1 cells an axis)
    return np.sort(_dense_representatives(points, bounding_box(points)[0],
                                          coarse_cell(points, PLAN_CELLS)))


@njit(cache=True)
def _dense_representatives(points, origin, cell):
    """:func:`_cell_representatives` of every occupied cell (nothing avoided), over a dense
    array of all the grid's cells (for coarse grids only)."""
    n = points.shape[0]
    dims = np.zeros(3, np.int64)
    for i in range(n):
        for t in range(3):
            dims[t] = max(dims[t], cell_ijk(points[i, t], origin, cell, t) + 1)
    best = np.full(dims[0] * dims[1] * dims[2], -1, np.int64)
    best_d = np.empty(best.shape[0])
    for i in range(n):
        c = 0
        d = 0.0
        for t in range(3):
            ijk = cell_ijk(points[i, t], origin, cell, t)
            c = c * dims[t] + ijk
            center = origin[t] + (ijk + 0.5) * cell
            d += (points[i, t] - center) ** 2
        b = best[c]
        if b < 0 or d < best_d[c] or (d == best_d[c] and (
                points[i, 0], points[i, 1], points[i, 2]) < (points[b, 0], points[b, 1],
                                                             points[b, 2])):
            best[c] = i
            best_d[c] = d
    return best[best >= 0]


def plan_auto(points: np.ndarray, tree: tuple, noise_threshold: float,
              dense_noise: float = np.inf, sample: np.ndarray | None = None) -> AutoPlan:
    """Measure spacing and noise on a geometric subsample of the cloud.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        The cloud (at least 10 points).
    tree : tuple
        :func:`~curvature.neighborhoods.kdtree.build_tree` over ``points``.
    noise_threshold : float
        Relative noise below which the cloud counts as clean.
    dense_noise : float
        Relative noise above which the fits see a thinned cloud (:data:`DENSE_TARGET`); its
        own plan is measured on the whole cloud thinned.
    sample : ndarray, shape (s,), int64, optional
        :func:`plan_sample` of ``points``, if the caller has it already.

    Returns
    -------
    AutoPlan
    """
    origin = bounding_box(points)[0]
    if sample is None:
        sample = plan_sample(points)
    k = min(PLAN_K, points.shape[0] - 1)
    indptr, indices, d2 = knn_csr(points, tree, sample, k)
    spacing = float(np.median(np.sqrt(d2[:, -1])))
    m = sample.shape[0]
    outs = [np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3)),
            np.empty(m), np.empty(m, np.int8)]
    fit_batch(points, sample, indptr, indices, FIT_MONGE, SOLVER_TAUBIN, True, 0.0, *outs)
    residual = outs[5][outs[6] == Status.OK]
    noise = _relative_median(residual, spacing)
    if not spacing > 0.0:  # every point coincides with its 24 nearest: any cell works
        spacing = coarse_cell(points, PLAN_CELLS)
    fine = cubic_noise(points, sample, indices.reshape(m, k)) if k >= 12 else residual
    fine_noise = _relative_median(fine, spacing)
    plan = AutoPlan(spacing=spacing, noise=noise, clean=bool(fine_noise < noise_threshold),
                    origin=tuple(float(v) for v in origin), cell=ANCHOR_CELL * spacing,
                    points=int(points.shape[0]), cubic_noise=fine_noise)
    if plan.clean or not np.isfinite(dense_noise) or points.shape[0] <= DENSE_K:
        return plan
    # Where the noise is comparable to the spacing the 24 nearest neighbors lie within the
    # noise and say little of either; over DENSE_K neighbors the patch is far wider than the
    # noise, the fit's residual is the noise and the patch's area gives the true spacing.
    indptr, indices, d2 = knn_csr(points, tree, sample, DENSE_K)
    fit_batch(points, sample, indptr, indices, FIT_MONGE, SOLVER_TAUBIN, True, 0.0, *outs)
    residual = outs[5][outs[6] == Status.OK]
    wide_spacing = float(np.median(np.sqrt(d2[:, -1]))) * np.sqrt(PLAN_K / DENSE_K)
    if not (residual.size and wide_spacing > 0.0):
        return plan
    wide_noise = float(np.median(residual)) / wide_spacing
    plan = replace(plan, wide_noise=wide_noise)
    # A wide patch that reaches a wall's other side or over a feature has a residual far above
    # the noise: then the cloud is not dense, it is thin (measured: 17 times the 24-neighbor
    # figure on a plate 4 spacings thick, 1.4 to 2.5 on dense and on ordinary noisy clouds).
    if not wide_noise > dense_noise or wide_noise > DENSE_CONSISTENT * noise:
        return plan
    # Thinned by t, the relative noise falls as 1 / sqrt(t) (same noise, sqrt(t) the spacing).
    share = (DENSE_TARGET / wide_noise) ** 2
    if share >= 1.0:
        return plan
    keep = np.ones(points.shape[0], np.bool_)
    thinned(points, share, keep)
    kept = points[keep]
    if kept.shape[0] <= DENSE_K:
        return plan
    dense = plan_auto(kept, build_tree(kept), noise_threshold)
    return replace(plan, dense_share=float(share), dense=replace(dense, clean=False))


def wide_fits(params: dict, plan: AutoPlan) -> bool:
    """Whether the fits on a cloud of this (whole-cloud) plan may reach ``k`` beyond
    :data:`QUIET_K`: a noisy plan, not dense, with relative noise above ``wide_noise``."""
    return not plan.clean and plan.dense is None and plan.noise > params["wide_noise"]


def largest_fit(params: dict, plan: AutoPlan, widen: bool = True) -> int:
    """Neighbors of the widest fit a cloud of this plan may get, before the share limits of
    :meth:`AutoRun.fit_k`: ``k``, at most :data:`QUIET_K` unless :func:`wide_fits`, at
    most :data:`BASE_K` unless ``widen``."""
    if not widen:
        return min(params["k"], BASE_K)
    return params["k"] if wide_fits(params, plan) else min(params["k"], QUIET_K)


def side_limit(params: dict, plan: AutoPlan, widen: bool = True) -> float:
    """The ``side_limit`` of the fits beyond :data:`BASE_K` on a cloud of this plan
    (:func:`~curvature.fitting.scale_selection.multiscale_anchor_fits`): :data:`QUIET_SIDE`
    where they stop at :data:`QUIET_K`, none on noisier clouds (at 0.4-0.5 % noise the Bezier
    patch's border gains more from the 1536 top's averaging than its bias costs: ratios to
    the best CGAL jet of its 0.4-0.5 % cells 0.50-0.52 with a limit of 0.12, 0.49-0.50
    without)."""
    return np.inf if widen and wide_fits(params, plan) else QUIET_SIDE


def thinned_points(points: np.ndarray, share: float) -> np.ndarray:
    """Indices (increasing, int64) of the points a dense cloud's fits see
    (:func:`~.sampling.thinned`)."""
    keep = np.ones(points.shape[0], bool)
    thinned(points, share, keep)
    return np.flatnonzero(keep).astype(np.int64)


def dense_stage1(points, tree, cand, spacing: float, k: int, normal_k: int, chunk_size: int,
                 tick=None):
    """Stage-1 normals and outlier tests of a dense cloud's thinned points, from one query.

    Only the thinned points are fitted and the outlier tests only decide which of them are,
    so no other point needs them. The first ``normal_k`` of a point's ``k`` neighbors are the
    ones a ``normal_k`` query gives (ties break by index), so the tests are those of the other
    branches. A function of the whole cloud at each point: a tiled run computes it once for
    all tiles (:class:`~curvature.pipeline.tiling.TiledRun`), with the same values as a
    run over the whole cloud.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    tree : tuple
        :func:`~curvature.neighborhoods.kdtree.build_tree` over ``points``.
    cand : ndarray, shape (m,), int64
        The thinned points (:func:`thinned_points`).
    spacing : float
        The plan's spacing (outlier test).
    k, normal_k : int
        Neighbors of the normals and of the outlier tests.
    chunk_size : int
        Points of a 24-neighbor chunk; chunks hold as many neighbor entries.
    tick : callable, optional
        Called with the count of points done after each chunk.

    Returns
    -------
    cand : ndarray, shape (m,), int64
    field : ndarray, shape (m, 3)
        PCA normals over ``k`` neighbors.
    r_normal : ndarray, shape (m,)
        Distance to the ``k``-th neighbor.
    outlier : ndarray, shape (m,), bool
    flat : ndarray, shape (m,)
        How far each ``k``-neighborhood is from a plane (:func:`pca_flatness`): where a
        rounded edge may be (:meth:`AutoRun._dense_edge_reads`).
    """
    m = cand.shape[0]
    kiso = min(ISOLATION_K, k)
    field, r_normal, flat = np.empty((m, 3)), np.empty(m), np.empty(m)
    r_isolation, outlier = np.empty(m), np.zeros(m, bool)
    own = np.empty((m, 3))  # each point's normal over its normal_k neighbors
    step = max(64, chunk_size * 24 // k)  # neighbor entries of a 24-neighbor chunk
    for sl in (slice(i, min(i + step, m)) for i in range(0, m, step)):
        query = cand[sl]
        indptr, indices, d2 = knn_csr(points, tree, query, k)
        nbr = indices.reshape(-1, k)
        r_normal[sl] = np.sqrt(d2[:, -1])
        r_isolation[sl] = np.sqrt(d2[:, kiso - 1])
        pca_flatness(points, query, indptr, indices, field[sl], flat[sl])
        pca_normals(points, query, *_prefix_csr(nbr, normal_k), own[sl])
        off_surface(points, query, np.ascontiguousarray(nbr[:, :normal_k]), own[sl], spacing,
                    outlier[sl])
        if tick is not None:
            tick(sl.stop - sl.start)
    del own
    isolated(points, tree, r_isolation, outlier, rows=cand)
    return cand, field, r_normal, outlier, flat


def whole_dense_stage1(points, tree, plan: AutoPlan, params: dict, chunk_size: int,
                       tick=None, cand=None) -> tuple:
    """:func:`dense_stage1` of a whole dense cloud, at its thinned points ``cand``
    (:func:`thinned_points` if not given), with normals over as many of the cloud's points as
    the share leaves out (``normal_k / share``, at most :data:`DENSE_NORMAL_K`). Made by
    :meth:`AutoRun.run`, or once by a tiled run for all its tiles."""
    n = points.shape[0]
    normal_k = min(params["normal_k"], n - 1)
    if cand is None:
        cand = thinned_points(points, plan.dense_share)
    k = min(max(int(round(params["normal_k"] / plan.dense_share)), normal_k), DENSE_NORMAL_K,
            n - 1)
    return dense_stage1(points, tree, cand, plan.spacing, k, normal_k, chunk_size, tick)


def neighbor_rows(points, tree, graph, chunk_size: int, rows=None, tick=None) -> None:
    """The ``graph.shape[1]`` nearest neighbors (each point first) of ``rows`` (increasing
    int64; default every point) into ``graph[rows]``, in chunks.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    tree : tuple
        :func:`~curvature.neighborhoods.kdtree.build_tree` over ``points``.
    graph : ndarray, shape (n, g), int32
    chunk_size : int
    rows : ndarray, shape (m,), int64, optional
    tick : callable, optional
        Called with the count of rows done after each chunk.
    """
    k = graph.shape[1]
    count = points.shape[0] if rows is None else rows.shape[0]
    for start in range(0, count, chunk_size):
        stop = min(start + chunk_size, count)
        query = np.arange(start, stop, dtype=np.int64) if rows is None else rows[start:stop]
        graph[query] = knn_csr(points, tree, query, k)[1].reshape(-1, k)
        if tick is not None:
            tick(stop - start)


class AutoRun:
    """One run of the auto estimator over a (Z-ordered) cloud, filling a result in place.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    params : dict
        Checked :data:`AUTO_PARAMS`.
    chunk_size : int
        Points (or anchors) per chunk; bounds the neighbor lists held at once.
    progress : callable or None
        ``progress(done, total)``.
    plan : AutoPlan, optional
        Cloud-wide measurements; measured on ``points`` when not given (a tile of a bigger
        cloud gets the whole cloud's plan).
    track_reach : bool
        Also compute :attr:`reach`: for every point, a distance within which every point its
        result depends on lies (tiling checks its halo with it).
    """

    def __init__(self, points, params, chunk_size, progress, plan: AutoPlan | None = None,
                 track_reach: bool = False):
        self.points = points
        self.params = params
        self.chunk_size = chunk_size
        self.progress = progress
        t0 = time.perf_counter()
        self._tree = None
        self.plan = plan_auto(points, self.tree, params["noise_threshold"],
                              params["dense_noise"]) if plan is None else plan
        self.timings: dict[str, float] = {"plan": time.perf_counter() - t0}
        release_freed_memory()
        self.track_reach = track_reach
        self.reach: np.ndarray | None = None
        self.outliers = np.zeros(points.shape[0], bool)
        # Points whose stage-1 normal was read over one side of a thin wall (_stage1): their
        # fits keep to that side where their lists hold both (_fit_lists)
        self.sided = np.zeros(points.shape[0], bool)
        # Points whose stage-1 normal belongs elsewhere (the cloud's border) and the offsets
        # the first pass reads them at (curvature.fitting.border_shift); none on a dense
        # cloud's thinned share, whose normals come from the whole cloud.
        self.shift_rows = np.empty(0, np.int64)
        self.shifts = np.empty((0, 3))
        self.edge_candidates = np.empty(0, np.int64)  # points tried for a rounded edge
        # Points a circle across a rounded thin edge read (:meth:`_store_rounded_edges`): no
        # cylinder fit replaces them (it would span the edge's two sides)
        self.edge_read = np.zeros(points.shape[0], bool)
        # Points whose standard errors are their own fit's, which the neighbor spread does
        # not widen (the sphere and cylinder fits; curvature.pipeline.widen_by_neighbors)
        self.own_std = np.zeros(points.shape[0], bool)
        # The share of the hash (:func:`thinned_points`) these points are, of the cloud they
        # were thinned from (1: none); a coarser share of them must thin further below it.
        self.hash_share = 1.0
        # RMS neighbor distance of each clean fit (its standard error's unit)
        self.clean_h = np.empty(points.shape[0]) if self.plan.clean else None
        # PCA normals over TURN_MONGE_K neighbors, which the Monge rungs' curvature must turn
        # (scale_selection.ladder_estimates; noisy clouds, not a dense cloud's thinned share)
        self.turn_normals: np.ndarray | None = None
        # Whether the fits may reach beyond BASE_K (fit_k); not on a dense cloud's thinned
        # share
        self.widen = True

    @property
    def tree(self) -> tuple:
        """The k-d tree over the points, built at first use: a tile of a dense cloud whose
        stage-1 work was done for the whole cloud needs none."""
        if self._tree is None:
            self._tree = build_tree(self.points)
        return self._tree

    @tree.setter
    def tree(self, value) -> None:
        self._tree = value

    def run(self, res, graph, orient_k: int, rows: np.ndarray | None = None,
            dense_stage1: tuple | None = None) -> None:
        """Fill every output array of ``res`` and the orientation graph (n, orient_k).

        ``rows`` (increasing int64 indices), if given, are the only points whose results are
        wanted (a tile's own points); the other rows of ``res`` and ``graph`` are left
        unfilled. Dense clouds then skip the other points' stage-1 work, and dense and noisy
        clouds the second pass, refits and reads that only other points need; clean clouds
        compute every row. ``dense_stage1`` (dense clouds only): the output of
        :func:`dense_stage1` for these points, computed beforehand (indices into them).
        """
        n = self.points.shape[0]
        k_stage1 = min(max(self.params["normal_k"], PLAN_K, orient_k), n - 1)
        kc = min(self.fit_k(), n - 1)
        self._done = 0
        if dense_stage1 is not None and self.plan.dense is None:
            raise ValueError("dense_stage1 is given but the plan is not dense")
        if self.plan.dense is not None:
            self._dense(res, graph, np.arange(n, dtype=np.int64) if rows is None else rows,
                        dense_stage1)
            return
        self._total = 2 * n
        t0 = time.perf_counter()
        field, radius = self._stage1(res, graph, k_stage1)
        release_freed_memory()
        # Anchors among the inliers (an outlier cannot anchor its cell's fits); outliers'
        # normals are left out of every fit.
        reps, owner = grid_cells(self.points, np.asarray(self.plan.origin), self.plan.cell,
                                 avoid=self.outliers)
        field[self.outliers] = np.nan
        if self.turn_normals is not None:
            self.turn_normals[self.outliers] = np.nan
        self._total += 0 if self.plan.clean else 2 * reps.shape[0]
        self.timings["stage1"] = time.perf_counter() - t0
        if self.track_reach:
            self.reach = radius[1] if self.plan.clean else np.zeros(n)
        if self.plan.clean:
            t0 = time.perf_counter()
            reach = np.empty(n)
            adopt_neighbor_fits(self.points, self.tree, min(PLAN_K, n - 1),
                                res.residual.copy(), res.neighbor_count.astype(np.int64),
                                radius[1], CLEAN_EXACT * self.plan.spacing,
                                CLEAN_ON_SURFACE * self.plan.spacing, *_outputs(res, slice(None)),
                                res.neighbor_count, reach)
            self.timings["adopt"] = time.perf_counter() - t0
            if self.track_reach:
                self.reach = reach
            self._clean_std(res)
            failed = np.flatnonzero(res.status != Status.OK)
            if failed.size:  # rare: an implicit fit failed; its cell anchor's field takes over
                self._fallback(res, field, radius[0], reps, owner, max(kc // 2, 12), failed)
            self._wedge_tips(res, np.arange(n, dtype=np.int64), kc,
                             max(self._noise(), CLEAN_WEDGE_NOISE * self.plan.spacing))
            return
        # Handed over in a list so that nothing here keeps them once the fits are made.
        stage1 = [field, radius[0]]
        del field, radius
        self._anchored(res, stage1, reps, owner, kc, rows)

    def share_k(self) -> int:
        """``max_share`` of the cloud's points (at least 48)."""
        return max(SHARE_MIN_K, int(self.params["max_share"] * self.plan.points))

    def fit_k(self) -> int:
        """Neighbors of the noisy branch's largest fits: ``k`` (at most :data:`QUIET_K` on
        clouds quieter than ``wide_noise``, :func:`largest_fit`), lowered on small clouds to
        :data:`SHARE_TOPS` times :meth:`share_k` (:data:`WIDE_SHARE_TOPS` times, where ``k``
        exceeds :data:`BASE_K`, on clouds of :data:`WIDE_MIN_POINTS` and more). Over a large
        share of a small cloud a fit reaches around whole features (across a thin torus's
        tube; docs/accuracy.md section 8), so a fit over :meth:`share_k` neighbors is always
        among the tops it falls back to (:func:`~curvature.fitting.scale_selection.pass_rungs`).
        """
        k = largest_fit(self.params, self.plan, self.widen)
        wide = k > BASE_K
        tops = WIDE_SHARE_TOPS if wide and self.plan.points >= WIDE_MIN_POINTS else SHARE_TOPS
        return min(k, tops * self.share_k())

    def _grow_total(self, count: int) -> None:
        """Count ``count`` more steps of work, found only as the run goes."""
        self._total += count

    def _tick(self, count: int) -> None:
        self._done += count
        if self.progress is not None:
            self.progress(min(self._done, self._total), self._total)

    def _chunks(self, count: int):
        for start in range(0, count, self.chunk_size):
            yield slice(start, min(start + self.chunk_size, count))

    def _stage1(self, res, graph, k: int):
        """PCA normals of every point; on clean clouds also the implicit fits.

        Returns the normals (n, 3) and two radii (n,): of the PCA neighborhoods and of the
        implicit fits' neighborhoods (clean clouds).
        """
        n = self.points.shape[0]
        field = np.empty((n, 3))
        normal_k = min(self.params["normal_k"], k)
        kp = min(PLAN_K, k)
        r_normal = np.empty(n)
        r_fit = np.empty(n) if self.plan.clean else None
        r_isolation = np.empty(n)
        flat = np.empty(n)
        rows, shifts = [np.empty(0, np.int64)], [np.empty((0, 3))]
        if not self.plan.clean:
            self.turn_normals = np.empty((n, 3))
        # the sheet test's candidates and their nearest neighbors (_off_sheets)
        walls, wall_nbr = [np.empty(0, np.int64)], [np.empty((0, min(OWN_SHEET_K, k)), np.int32)]
        for sl in self._chunks(n):
            query = np.arange(sl.start, sl.stop, dtype=np.int64)
            indptr, indices, d2 = knn_csr(self.points, self.tree, query, k)
            nbr = indices.reshape(-1, k)
            r_normal[sl] = np.sqrt(d2[:, normal_k - 1])
            if graph is not None:
                graph[sl] = nbr[:, :graph.shape[1]]
            pca_flatness(self.points, query, *_prefix_csr(nbr, normal_k), field[sl], flat[sl])
            if self.turn_normals is not None:
                pca_normals(self.points, query, *_prefix_csr(nbr, min(TURN_MONGE_K, k)),
                            self.turn_normals[sl])
            off_surface(self.points, query, np.ascontiguousarray(nbr[:, :normal_k]), field[sl],
                        self.plan.spacing, self.outliers[sl])
            if not self.plan.clean:
                thick = np.flatnonzero(flat[sl] > OWN_SHEET_CANDIDATE)
                walls.append(query[thick])
                wall_nbr.append(nbr[thick, :OWN_SHEET_K])
                offsets = np.empty((query.shape[0], 3))
                border_offsets(self.points, query, nbr[:, :normal_k], field[sl], r_normal[sl],
                               offsets)
                moved = np.flatnonzero(np.any(offsets != 0.0, axis=1))
                rows.append(query[moved])
                shifts.append(offsets[moved])
                if moved.size:
                    # The border's normals, read at their centroids, are the tangent planes'
                    # there rather than the PCA planes' (border_shift.centroid_normals).
                    centred = np.empty((moved.size, 3))
                    centroid_normals(self.points, query[moved],
                                     np.ascontiguousarray(nbr[moved, :normal_k]),
                                     field[sl][moved], centred)
                    field[sl.start + moved] = centred
            r_isolation[sl] = np.sqrt(d2[:, min(ISOLATION_K, k) - 1])
            if self.plan.clean:
                self._clean_fits(res, sl, query, nbr, d2, kp)
                r_fit[sl] = np.sqrt(d2[:, kp - 1])
            self._tick(2 * (sl.stop - sl.start) if self.plan.clean else sl.stop - sl.start)
        isolated(self.points, self.tree, r_isolation, self.outliers)
        walls = np.concatenate(walls)
        if not self.plan.clean:
            self._off_sheets(field, walls, np.concatenate(wall_nbr), r_isolation)
        del wall_nbr
        renormalled = self._normals_without_outliers(field, r_normal, normal_k)
        rows, shifts = np.concatenate(rows), np.concatenate(shifts)
        sided = (np.empty(0, np.int64) if self.plan.clean
                 else self._normals_of_one_side(field, flat, r_normal, normal_k))
        if not self.plan.clean:
            renormalled, sided = self._between_faces(field, flat, r_normal, normal_k, walls,
                                                     renormalled, sided)
        del walls
        self.sided[sided] = True
        # Neighborhoods far from flat, beyond what noise makes of a flat one: where a rounded
        # edge may be (_rounded_edges).
        self.edge_candidates = np.flatnonzero(worth_trying(flat, r_normal, self._noise())
                                              & ~self.outliers)
        del flat
        # Offsets of normals refitted without outliers or over one side of a wall, or of
        # outliers, would not match (a wall's two faces make its PCA neighborhoods look cut
        # by a border: 8 to 11 % of the bench's plate and blade were moved).
        keep = ~self.outliers[rows] & ~np.isin(rows, renormalled) & ~np.isin(rows, sided)
        self.shift_rows, self.shifts = rows[keep], shifts[keep]
        return field, (r_normal, r_fit)

    def _off_sheets(self, field, rows, nbr, reach) -> None:
        """Flag as outliers, in ``self.outliers``, the points on no sheet of their nearest
        neighbors (:func:`~curvature.fitting.outliers.off_sheets`: inside a thin wall, past a
        wedge's tip) among ``rows`` (r,), the points whose stage-1 neighborhood is far from
        flat, with their nearest neighbors ``nbr`` (r, OWN_SHEET_K) from the stage-1 query;
        ``field`` (n, 3) the stage-1 normals, ``reach`` (n,) each point's distance to its
        ISOLATION_K-th neighbor."""
        limit = sheet_limit(self._noise(), self.plan.spacing)
        test = ~self.outliers[rows]
        rows, nbr = rows[test], np.ascontiguousarray(nbr[test])
        if not np.isfinite(limit) or rows.size == 0 or nbr.shape[1] < 1:
            return
        found = np.zeros(rows.size, bool)
        off_sheets(self.points, rows, nbr, field, reach, self.outliers, limit, found)
        self.outliers[rows[found]] = True

    def _between_faces(self, field, flat, r_normal, normal_k, walls, renormalled, sided):
        """Flag as outliers, in ``self.outliers``, the candidates ``walls`` whose neighbors
        lie on two parallel faces of a thin wall and that lie on neither
        (:func:`~curvature.fitting.outliers.between_faces`), judged by the wall's one-sided
        normals (``sided``); then refit the normals they tilted, one-sided again on the
        wall. Returns the rows refitted without outliers and those read over one side, as
        updated.
        """
        test = walls[~self.outliers[walls]]
        k = min(FACE_K, self.points.shape[0] - 1)
        fresh = [np.empty(0, np.int64)]
        noise = self._noise()
        for start in range(0, test.size, self.chunk_size):
            query = test[start:start + self.chunk_size]
            found = np.empty(query.size, bool)
            between_faces(self.points, query, np.ascontiguousarray(self._nearest(query, k)[0]),
                          field, self.outliers, noise, found)
            fresh.append(query[found])
        fresh = np.concatenate(fresh)
        if fresh.size == 0:
            return renormalled, sided
        # all flagged at once: a point's verdict does not depend on the chunk it was in
        self.outliers[fresh] = True
        again = self._normals_without_outliers(field, r_normal, normal_k, fresh)
        only = np.zeros_like(flat)
        only[again] = flat[again]
        resided = self._normals_of_one_side(field, only, r_normal, normal_k)
        sided = np.union1d(np.setdiff1d(sided, np.union1d(again, fresh)), resided)
        return np.union1d(renormalled, again), sided

    def _normals_of_one_side(self, field, flat, r_normal, normal_k) -> np.ndarray:
        """Stage-1 normals on thin walls over one side (:mod:`.wall_sides`), in ``field``;
        returns the rows replaced."""
        n = self.points.shape[0]

        def nearest(rows, k):
            return knn_csr(self.points, self.tree, rows, k)[1].reshape(-1, k)

        return one_side_normals(self.points, field, flat, r_normal, self._noise(),
                                self.outliers, nearest, min(normal_k, n - 1), self.chunk_size)

    def _noise(self) -> float:
        """The cloud's noise in length units (standard deviation across the surface): the
        plan's cubic-fit residual over :data:`NOISE_RESIDUAL_SHARE`."""
        return self.plan.cubic_noise * self.plan.spacing / NOISE_RESIDUAL_SHARE

    def _normals_without_outliers(self, field, r_normal, normal_k, out=None,
                                  rounds=UNMASK_ROUNDS) -> np.ndarray:
        """Stage-1 normals again, without the outliers, where one (of ``out``, int64, if
        given; else any) was among the neighbors; and those points' outlier test
        (:func:`~curvature.fitting.outliers.off_surface`) again without them, up to
        ``rounds`` times more for the points it flags.

        One outlier a spacing off a face tilts the PCA normals of every point that has it among
        its ``normal_k`` neighbors, and the normal fits then read that tilt as curvature. Two
        outliers near each other hide each other: each raises the other's neighbors'
        thickness (the blade's seed 1: one 9 noise off a side by its border was not flagged
        while one 16 noise off stood among its neighbors).
        Returns the rows whose normals were refitted (int64).
        """
        if out is None:
            out = np.flatnonzero(self.outliers)
        if out.size == 0:
            return np.empty(0, np.int64)
        d, _ = cKDTree(self.points[out]).query(self.points, k=1,
                                                workers=numba.get_num_threads())
        hit = np.flatnonzero((d <= r_normal) & ~self.outliers).astype(np.int64)
        k = min(normal_k + RENORMAL_EXTRA, self.points.shape[0] - 1)
        fresh = [np.empty(0, np.int64)]
        for start in range(0, hit.size, self.chunk_size):
            rows = hit[start:start + self.chunk_size]
            _, indices, d2 = knn_csr(self.points, self.tree, rows, k)
            nbr = indices.reshape(-1, k)
            inlier = ~self.outliers[nbr]
            use = inlier & (np.cumsum(inlier, axis=1) <= normal_k)
            counts = use.sum(axis=1)
            indptr = np.zeros(rows.size + 1, np.int64)
            np.cumsum(counts, out=indptr[1:])
            normals = np.empty((rows.size, 3))
            pca_normals(self.points, rows, indptr, nbr[use], normals)
            field[rows] = normals
            last = np.where(use, np.sqrt(d2), 0.0).max(axis=1)
            r_normal[rows] = np.maximum(r_normal[rows], last)
            if rounds > 0:
                full = np.flatnonzero(counts == normal_k)  # (fewer: too many outliers near)
                found = np.zeros(full.size, bool)
                off_surface(self.points, rows[full], nbr[full][use[full]].reshape(-1, normal_k),
                            normals[full], self.plan.spacing, found)
                fresh.append(rows[full[found]])
        fresh = np.concatenate(fresh)
        if fresh.size == 0:
            return hit
        # all flagged at once: a point's verdict does not depend on the chunk it was in
        self.outliers[fresh] = True
        again = self._normals_without_outliers(field, r_normal, normal_k, fresh, rounds - 1)
        return np.union1d(hit, again)

    def _clean_fits(self, res, sl, query, nbr, d2, kp) -> None:
        """Implicit quadrics of a chunk of a clean cloud, written to ``res`` rows ``sl``.

        Over ``kp`` (24) neighbors first; where that fit is not exact, also over 16 and 12,
        keeping the largest whose residual distance is within :data:`CLEAN_RESIDUAL_RATIO` of
        the smallest: a fit that straddles a curvature jump (a face beside a fillet) has a far
        larger residual than one on a single piece, while on smooth non-quadric surfaces the
        residuals grow slowly with size and 24 stays. A kept fit whose curvature the points
        do not support (``|k| h`` above :data:`CLEAN_SUPPORT`), or an inexact one the height
        quadric over its points does not confirm (:mod:`~curvature.fitting.height_check`), is
        marked degenerate; :meth:`run` gives such points an exact neighbor's fit or the
        anchored fits.
        """
        fit_batch(self.points, query, *_prefix_csr(nbr, kp), FIT_IMPLICIT, SOLVER_TAUBIN, True,
                  0.0, *_outputs(res, sl))
        res.neighbor_count[sl] = kp
        floor = CLEAN_EXACT * self.plan.spacing
        rows = np.flatnonzero(~(res.residual[sl] <= floor))  # NaN (failed) included
        best = res.residual[sl][rows].copy()
        best[~np.isfinite(best)] = np.inf
        for size in CLEAN_SIZES:
            if size >= kp or rows.size == 0:
                continue
            out = _OutputView(res, sl.start + rows)
            fit_batch(self.points, query[rows], *_prefix_csr(nbr[rows], size), FIT_IMPLICIT,
                      SOLVER_TAUBIN, True, 0.0, *out.arrays)
            resid = np.where(out.arrays[6] == Status.OK, out.arrays[5], np.inf)
            best = np.minimum(best, resid)
            # Sizes go down: keep this one only where the larger kept one is not near the best.
            kept = res.residual[sl][rows]
            take = ~(kept <= CLEAN_RESIDUAL_RATIO * best + floor) & (resid < np.inf)
            if take.any():
                out.rows, out.arrays = out.rows[take], tuple(a[take] for a in out.arrays)
                out.store(size)
        count = res.neighbor_count[sl]
        h = np.sqrt(np.take_along_axis(np.cumsum(d2, axis=1), count[:, None] - 1,
                                       axis=1)[:, 0] / count)
        self.clean_h[sl] = h
        curv = np.maximum(np.abs(res.k1[sl]), np.abs(res.k2[sl]))
        loose = curv * h > CLEAN_SUPPORT
        inexact = np.flatnonzero((res.residual[sl] > floor) & (res.status[sl] == Status.OK))
        loose[inexact] |= self._unconfirmed(res, sl, query, nbr, h, inexact)
        rows = sl.start + np.flatnonzero(loose)
        for arr in (res.k1, res.k2, res.residual):
            arr[rows] = np.nan
        for arr in (res.normals, res.dir1, res.dir2):
            arr[rows] = np.nan
        res.status[rows] = Status.DEGENERATE_FIT

    def _unconfirmed(self, res, sl, query, nbr, h, rows) -> np.ndarray:
        """Which of the inexact implicit fits ``rows`` (indices into chunk ``sl``) the height
        quadric over the same neighbors does not confirm (:mod:`.height_check`); ``h`` (chunk,)
        is their RMS neighbor distance."""
        off = np.zeros(rows.shape[0], bool)
        count = res.neighbor_count[sl][rows]
        for size in np.unique(count):
            grp = np.flatnonzero(count == size)
            out = _OutputView(res, sl.start + rows[grp])
            fit_batch(self.points, query[rows[grp]], *_prefix_csr(nbr[rows[grp]], int(size)),
                      FIT_MONGE, SOLVER_TAUBIN, True, 0.0, *out.arrays)
            off[grp] = unconfirmed(res.k1[sl][rows[grp]], res.k2[sl][rows[grp]],
                                   out.arrays[0], out.arrays[1], h[rows[grp]])
        return off

    def _clean_std(self, res) -> None:
        """Standard errors of the clean fits: the model error their residual implies."""
        with np.errstate(invalid="ignore", divide="ignore"):
            std = CLEAN_CALIBRATION * res.residual / self.clean_h ** 2
        std = with_floor(np.where(res.status == Status.OK, std, np.nan), res.k1, res.k2,
                         1.0 / self.plan.spacing)
        res.k1_std[:] = std
        res.k2_std[:] = std
        res.mean_std[:] = std

    def _anchored(self, res, stage1: list, reps, owner, kc, rows=None) -> None:
        """Two passes of anchored normal fits over ``kc`` neighbors of every anchor, read at
        every point (or at ``rows``) but those that get fits of their own (:meth:`_refit`).
        ``stage1`` holds the stage-1 normals and their radii (emptied here).

        With ``rows`` the second pass fits only the anchors those rows read and the anchors
        within :data:`REFIT_ZONE` cells of them, which decide whether they are refitted.
        """
        n = self.points.shape[0]
        wanted = None if rows is None else self._zone_anchors(reps, np.unique(owner[rows]))
        if wanted is not None:  # run() counted a second pass at every anchor
            self._total -= reps.shape[0] - wanted.shape[0]
        fits, fit_reach, chosen, err, field_reach = self._model(*stage1, reps, owner, kc,
                                                                wanted)
        if wanted is None:
            rows = np.arange(n, dtype=np.int64)
        else:  # anchors numbered as the second pass's fits are
            local = np.full(reps.shape[0], -1, np.int64)
            local[wanted] = np.arange(wanted.shape[0])
            owner = local[owner]  # -1 outside the wanted anchors' cells (no row there)
            reps = reps[wanted]
        zone, zone_reach = self._refit_zone(reps, chosen, fit_reach)
        in_zone = np.zeros(n, bool)
        in_zone[rows] = zone[owner[rows]]
        # stage1[0] now holds the refined normals the second pass fitted.
        own, own_reach = self._refit(res, stage1[0], field_reach, in_zone, kc)
        # At every point, not only at rows: the fits beside an edge leave out its points
        # wherever their lists reach, in a tile's halo too.
        reads = self._rounded_edges(np.arange(n, dtype=np.int64), kc)
        # (the last user of the second pass's normals: they are read again beside the edges)
        old = (reps, owner, chosen, own)  # each row's fit so far (own's sizes are in res)
        beside = self._beside_edges(res, *stage1, field_reach, reads, rows, kc, old)
        # The reads below need only the fits: the normals and their radii, and the tree (72
        # bytes a point together), go before the result pages the reads fill are touched.
        stage1.clear()
        del field_reach, in_zone
        self.tree = None
        release_freed_memory()
        t0 = time.perf_counter()
        anchored = np.zeros(n, bool)
        anchored[rows] = True
        anchored[own] = False
        for sl in self._chunks(n):
            query = (sl.start + np.flatnonzero(anchored[sl])).astype(np.int64)
            out = _OutputView(res, query, 1.0 / self.plan.spacing)
            nfr_from_anchors(self.points, query, owner[query], reps, *fits, *out.arrays)
            out.store(chosen[owner[query]], err[owner[query]])
            self._tick(sl.stop - sl.start)
        self.timings["pass2"] += time.perf_counter() - t0
        if self.track_reach:
            # Every point's result depends on whether an anchor of its zone kept a small fit.
            self.reach = np.full(n, np.nan)
            d = np.linalg.norm(self.points[rows] - self.points[reps[owner[rows]]], axis=1)
            self.reach[rows] = d + zone_reach[owner[rows]] + np.sqrt(3.0) * self.plan.cell
            self.reach[own] = np.maximum(self.reach[own], own_reach)
        if beside is not None:
            self._store_beside(*beside)
        for edges in reads:
            if edges is not None:
                self._store_rounded_edges(res, edges, rows)
        self._umbilic(res, rows, kc)

    def _umbilic(self, res, rows, kc) -> None:
        """Sphere and cylinder fits at ``rows`` where they read a point better than its
        estimate (:mod:`~curvature.estimators.umbilic_pass`; flat faces and sphere-like
        corners beside features, fillets), over at most ``kc`` neighbors (docs/accuracy.md
        section 9, steps 27 and 31), then the wedge tips (:meth:`_wedge_tips`)."""
        t0 = time.perf_counter()
        umbilic_pass(self.points, self._nearest, res, rows, self._noise(), kc, self.outliers,
                     self.chunk_size, self.reach if self.track_reach else None,
                     1.0 / self.plan.spacing, self._grow_total, self._tick,
                     cylinders=~self.edge_read, own_std=self.own_std)
        self.timings["umbilic"] = time.perf_counter() - t0
        self._wedge_tips(res, rows, kc, self._noise())
        self.tree = None

    def _nearest(self, idx, k):
        """The ``k`` nearest points of ``points[idx]``, nearest first: (nbr (m, k), d2 (m, k))."""
        _, indices, d2 = knn_csr(self.points, self.tree, idx, k)
        return indices.reshape(-1, k), d2

    def _wedge_tips(self, res, rows, kc, noise) -> None:
        """Fits at the tips of thin wedges (:mod:`~curvature.estimators.wedge_tip_pass`) at
        the rounded edges' candidates among ``rows``, over at most ``kc`` neighbors, with the
        cloud's ``noise`` (docs/accuracy.md section 9, steps 33 and 34)."""
        t0 = time.perf_counter()
        wedge_tip_pass(self.points, self._nearest, res, rows, noise, kc, self.outliers,
                       self.edge_candidates, self.chunk_size,
                       self.reach if self.track_reach else None, 1.0 / self.plan.spacing,
                       own_std=self.own_std)
        self.timings["wedge tips"] = time.perf_counter() - t0

    def _rounded_edges(self, rows, kc):
        """Circle fits across rounded thin edges (:mod:`~curvature.fitting.rounded_edge`) at
        the points of ``rows`` whose stage-1 neighborhood was far from flat
        (:data:`~curvature.fitting.rounded_edge.EDGE_FLAT`, ``EDGE_FLAT_NOISE``; the outliers
        left out) and whose nearest PCA normals fan
        out around an axis, over at most ``kc`` neighbors (the fits' largest size: a user's
        ``k`` holds for them too), read at those points where they lie on their circle; and
        the circles of coarser levels, read at the other points of the cloud that lie on them
        (:meth:`_coarse_edge_reads`).

        Returns
        -------
        fine, filled, coarse : tuple or None
            The reads at full density of the points' own circles, of the nearest such circle
            at the points that read none (:data:`FILL_REACH`), and of the coarser levels'
            circles; each None where no point reads one, else (points, k1, k2, normals, dir1,
            dir2, k1's and k2's standard errors, inliers, reach), one row per point.
        """
        t0 = time.perf_counter()
        try:
            return self._edge_reads(rows, kc)
        finally:
            self.timings["rounded edges"] = time.perf_counter() - t0

    def _edge_reads(self, rows, kc):
        """:meth:`_rounded_edges`."""
        circles = self._edge_circles(rows, kc)
        taken = np.zeros(self.points.shape[0], bool)  # the points that read a circle
        fine = filled = None
        if circles is not None:
            fine = _read_circles(circles, circles[0], None, self._noise())
        if fine is not None:
            taken[fine[0]] = True
            filled = self._filled_reads(circles, taken, taken)
        coarse = _joined([r for r in self._coarse_edge_reads(kc, taken) if r[0].size])
        return fine, filled, coarse

    def _confirmed(self, circles, own):
        """The circles (as :meth:`_edge_circles` returns them) whose own point reads them
        (``own`` (n,) bool) with :data:`FILL_CONFIRM` such points within :data:`FILL_REACH`
        of their list radius, and their centres (c, 3).

        Only circles their own point reads: not a box's corner, where a few cylinders fit but
        miss their own points (read at others they took a corner from 0.51 to 0.57).
        """
        circles = tuple(x[own[circles[0]]] for x in circles)
        centres = self.points[circles[0]]
        count = cKDTree(centres).query_ball_point(
            centres, FILL_REACH * circles[-1], return_length=True,
            workers=numba.get_num_threads())
        confirmed = count >= FILL_CONFIRM
        return tuple(x[confirmed] for x in circles), centres[confirmed]

    def _filled_reads(self, circles, own, taken, reader=None, noise=None):
        """The reads of the circles fitted on this cloud that :meth:`_confirmed` keeps (``own``
        (n,) bool: the points that read their own) at the points of ``reader`` (an
        :class:`AutoRun`; this one by default) no circle read yet (``taken``, updated), within
        :data:`FILL_REACH` of their list radius (:meth:`_offset_reads`); None where none
        does."""
        circles, centres = self._confirmed(circles, own)
        reads = (reader or self)._offset_reads(circles, centres, FILL_REACH, taken, noise)
        if reads is not None:
            taken[reads[0]] = True
            # (which circle a point reads, and whether it may, depends on the points that
            # read their own within FILL_REACH of its centre, and on their lists)
            reads = reads[:-1] + (2.0 * reads[-1],)
        return reads

    def _offset_reads(self, circles, centres, share, taken, noise=None):
        """The reads of ``circles`` (as :meth:`_edge_circles` returns them, fitted around
        ``centres`` (c, 3)) at the points no circle read yet (``taken`` (n,) bool) and no
        outliers: of the nearest of their :data:`READ_CIRCLES` nearest circles on whose arc
        they lie (:func:`_read_circles`, for a cloud of ``noise``: this cloud's by default),
        within ``share`` of its list radius of its centre; None where none does."""
        if centres.shape[0] == 0:
            return None
        noise = self._noise() if noise is None else noise
        done = taken | self.outliers
        open_ = np.flatnonzero(~done)
        count = min(READ_CIRCLES, centres.shape[0])
        # (beyond the widest reach no circle is read: those points' distances are inf)
        d, nearest = cKDTree(centres).query(self.points[open_], count,
                                            distance_upper_bound=share * circles[-1].max(),
                                            workers=numba.get_num_threads())
        d, nearest = d.reshape(-1, count), nearest.reshape(-1, count)
        reads = []
        for col in range(count):  # the nearest circle first, then the next ...
            found = np.isfinite(d[:, col])
            j = np.where(found, nearest[:, col], 0)
            near = np.flatnonzero(found & (d[:, col] <= share * circles[-1][j])
                                  & ~done[open_])
            j = j[near]
            near = open_[near]
            read = _read_circles(tuple(x[j] for x in circles), near,
                                 self.points[near] - centres[j], noise)
            if read is not None:
                done[read[0]] = True
                reads.append(read)
        return _joined(reads)

    def _coarse_edge_reads(self, kc, taken, reader=None) -> list:
        """Circles fitted on thinned shares of the cloud (:data:`COARSE_SHARES`), read at the
        points of ``reader`` (an :class:`AutoRun`; this one by default) no finer level's
        circle reads (``taken`` (reader's n,) bool, updated); one read tuple per level that
        has any.

        The circle fits' scale is set in neighbors (their ladder, the fan and flatness tests),
        so on a denser cloud an edge spans more spacings than a list reaches round: the
        100,000-point blade's leading edge (8 spacings' radius) read no circle, and its
        anchored fits read it 1.72 (the 20,000-point blade's circles 0.46). On a hash-thinned
        share (the same points in any order and tile) the edge spans fewer spacings again.
        Only circles of :data:`COARSE_MIN_RADIUS` plan spacings and more are read: those the
        full density's circles cannot reach round. At a quarter of the 100,000-point blade's
        points the wedge beside its trailing edge (its sides 2 to 4 thinned spacings apart)
        fits circles through both sides, of 0.9 to 1.6 plan spacings' radius: read, they
        raised the sides' error from 0.438 to 0.524.
        """
        n = self.points.shape[0]
        shares = [share for share in COARSE_SHARES if share * n >= COARSE_MIN_POINTS]
        # The flatness test runs at every point of the coarsest share only (a sixteenth),
        # and at a finer share only near that share's candidates: an edge that is not flat
        # at a finer share is not at a coarser one (its neighborhoods are wider), and on a
        # noisy cloud every point of a share would be tested otherwise (a 1M-point torus:
        # 0.56 s for one candidate).
        coarser = None  # the coarser share's candidates, and how far from them to look
        levels = []
        for share in shares[::-1]:
            idx = thinned_points(self.points, share * self.hash_share)
            idx = idx[~self.outliers[idx]]
            sub = AutoRun(np.ascontiguousarray(self.points[idx]), self.params, self.chunk_size,
                          None, plan=self.plan)
            seeds = np.arange(idx.shape[0], dtype=np.int64)
            seeded = 0.0  # how far beyond its own reach a circle's candidacy depends
            if coarser is not None:
                seeds = seeds[_within_any(*coarser, sub.points)]
                seeded = 1.5 * coarser[1]  # the coarser candidates' own neighborhoods too
            sub.edge_candidates = sub._flat_points(self._noise(), seeds)
            levels.append((idx, sub, seeded))
            # (twice the radius of a stage-1 neighborhood at this share)
            coarser = (sub.points[sub.edge_candidates], 2.0 * self.plan.spacing
                       * np.sqrt(self.params["normal_k"] / PLAN_K / share))
        out = []
        for idx, sub, seeded in levels[::-1]:  # finest share first
            circles = sub._edge_circles(np.arange(idx.shape[0], dtype=np.int64),
                                        min(kc, idx.shape[0] - 1))
            if circles is None:
                continue
            reads = (reader or self)._offset_reads(circles, sub.points[circles[0]], 1.0, taken,
                                                   self._noise())
            if reads is not None:
                # (the full density's circles read radii up to about 1.3 plan spacings)
                wide = np.fmax(np.abs(reads[1]), np.abs(reads[2])) * COARSE_MIN_RADIUS <= (
                    1.0 / self.plan.spacing)
                reads = tuple(x[wide] for x in reads[:-1]) + (reads[-1][wide] + seeded,)
                taken[reads[0]] = True
                out.append(reads)
        return out

    def _flat_points(self, noise, among) -> np.ndarray:
        """The points of ``among`` (int64) whose stage-1 neighborhood (``normal_k``
        nearest) is far from flat, as :meth:`_stage1`'s rounded-edge candidates, for a cloud
        of noise ``noise``."""
        n = self.points.shape[0]
        k = min(self.params["normal_k"], n - 1)
        found = [np.empty(0, np.int64)]
        for sl in self._chunks(among.shape[0]):
            query = among[sl]
            _, indices, d2 = knn_csr(self.points, self.tree, query, k + 1)
            normals, flat = np.empty((query.shape[0], 3)), np.empty(query.shape[0])
            pca_flatness(self.points, query, *_prefix_csr(indices.reshape(-1, k + 1)[:, 1:], k),
                         normals, flat)
            radius = np.sqrt(d2.reshape(-1, k + 1)[:, -1])
            found.append(query[worth_trying(flat, radius, noise)])
        return np.concatenate(found)

    def _edge_circles(self, rows, kc):
        """The usable circles around the candidate points of ``rows`` (None if none): the
        points, and their frames, circles, curvatures, standard errors, arcs, inlier counts
        and list radii (:func:`~curvature.fitting.rounded_edge.edge_circle_fits`)."""
        n = self.points.shape[0]
        ladder = np.asarray([k for k in EDGE_LADDER if k <= min(n - 1, kc)], np.int64)
        points = self.edge_candidates[np.isin(self.edge_candidates, rows)]
        if points.size == 0 or ladder.size == 0:
            return None
        normals = np.full((n, 3), np.nan)
        done = np.zeros(n, bool)
        fan = min(EDGE_FAN_K, n - 1)
        wide = [np.empty(0, np.int64)]
        for sl in self._chunks(points.shape[0]):
            indptr, indices, _ = knn_csr(self.points, self.tree, points[sl], fan)
            self._edge_normals(indices, normals, done)
            wide.append(points[sl][wraps(normals, points[sl], indptr, indices, FAN_MIN)])
        points = np.concatenate(wide)
        a = points.shape[0]
        if a == 0:
            return None
        frame, circle = np.empty((a, 3, 3)), np.empty((a, 3))
        curv, std, arc = np.empty((a, 2)), np.empty((a, 2)), np.empty((a, 2))
        count, ok, radius = np.zeros(a, np.int64), np.zeros(a, bool), np.empty(a)
        listed = int(ladder[-1])
        noise = self._noise()
        step = max(64, self.chunk_size * 24 // listed)
        for start in range(0, a, step):
            at = slice(start, min(start + step, a))
            indptr, indices, d2 = knn_csr(self.points, self.tree, points[at], listed)
            self._edge_normals(indices, normals, done)
            edge_circle_fits(self.points, normals, points[at], indptr, indices, noise, ladder,
                             frame[at], circle[at], curv[at], std[at], arc[at], count[at],
                             ok[at])
            radius[at] = np.sqrt(d2[:, -1])
        del normals, done
        if not ok.any():
            return None
        return tuple(x[ok] for x in (points, frame, circle, curv, std, arc, count, radius))

    def _beside_edges(self, res, field, r_normal, field_reach, reads, rows, kc, old):
        """Fits without the rounded edges (:mod:`.beside_edges`) at the points of ``rows``
        beside them, over up to ``kc`` neighbors. ``reads`` are the edges' reads as
        :meth:`_rounded_edges` returns them: the points beside the full density's own reads
        are fitted again, and those left out with the edges that read no circle (the faces
        past an arc's end). ``field`` holds the normals
        the second pass fitted (``field_reach``: how far each depends); those the edge bent
        are read again, in place, over the stage-1 neighborhoods (radii ``r_normal``) without
        it. ``old`` says which fit each row of ``res`` reads so far: (anchors, each point's
        anchor, the anchors' fit sizes, the rows refitted on their own, whose sizes ``res``
        holds); a row whose fit reached neither the edge nor a normal it bent keeps it. None
        where there is no edge or no point beside one, else (the fits read at the points, as
        an :class:`_OutputView` of ``res``, their sizes, standard errors and reach), for
        :meth:`_store_beside`.
        """
        if all(r is None for r in reads):
            return None
        t0 = time.perf_counter()
        try:
            return self._beside_fits(res, field, r_normal, field_reach, reads, rows, kc, old)
        finally:
            self.timings["beside edges"] = time.perf_counter() - t0

    def _beside_fits(self, res, field, r_normal, field_reach, reads, rows, kc, old):
        """:meth:`_beside_edges`."""
        fine, _, coarse = reads
        every = _joined(reads)  # every point that reads a circle is left out
        # The widening runs from the points that read their own circle or a coarser level's,
        # and the reach of the refits from those that read their own. Run from the filled
        # reads too (they lie at the arcs' ends as well), the refits reached farther onto the
        # faces, where the anchored fits read them better (the 20,000-point blade's sides
        # 0.146 -> 0.156, the bench's blade's +1.7 %).
        widened = _joined((fine, coarse))
        tree = cKDTree(self.points)
        if widened is None:
            drop = np.zeros(self.points.shape[0], bool)
        else:
            drop = edge_drop(tree, self.points, widened[0],
                             np.fmax(np.abs(widened[1]), np.abs(widened[2])))
        drop[every[0]] = True
        skip = self.outliers.copy()
        skip[every[0]] = True
        query = beside_rows(tree, self.points, rows, fine, drop, skip)
        if query.size == 0:
            return None
        edge, across = every[0], np.fmax(np.abs(every[1]), np.abs(every[2]))
        # Normals again wherever the fits may read one the edge bent: in a tile's halo too.
        bent = normals_near(tree, self.points, edge, across, drop, self.outliers, r_normal)
        del tree
        k = min(self.params["normal_k"] + 1, self.points.shape[0])
        touched = [np.empty(0, np.int64)]
        for sl in self._chunks(bent.shape[0]):
            nbr = knn_csr(self.points, self.tree, bent[sl], k)[1].reshape(-1, k)
            touched.append(one_sided_normals(self.points, bent[sl], nbr[:, 1:], drop, field))
        query = query[reached(self.points, query, *old, res.neighbor_count, r_normal,
                              self.params["normal_k"],
                              np.union1d(np.flatnonzero(drop), np.concatenate(touched)))]
        if query.size == 0:
            return None
        self._grow_total(query.shape[0])
        fits, fit_reach, size, err = self._fit_anchors(query, field, kc, field_reach, drop=drop)
        out = _OutputView(res, query, 1.0 / self.plan.spacing)  # (stored after the reads)
        nfr_from_anchors(self.points, query, np.arange(query.shape[0], dtype=np.int64), query,
                         *fits, *out.arrays)
        reach = None
        if self.track_reach:
            # Which points are left out depends on the circles within reach of the list (the
            # circles' own reach, the widening) and which points are refitted on those within
            # BESIDE_REACH of the point.
            edge_reach = float(every[-1].max())
            reach = fit_reach + widening(across).max() + (BESIDE_REACH + 1.0) * edge_reach
        return out, size, err, reach

    def _store_beside(self, out, size, err, reach) -> None:
        """Write the fits of :meth:`_beside_edges` into their result where they succeeded."""
        take = out.arrays[6] == Status.OK
        if self.track_reach:
            self.reach[out.rows] = np.fmax(self.reach[out.rows], reach)
        out.keep(take)
        out.store(size[take], err[take])

    def _edge_normals(self, indices, normals, done) -> None:
        """PCA normals over :data:`~curvature.fitting.rounded_edge.EDGE_NORMAL_K` neighbors
        at the points ``indices`` lists that have none yet (``done``), into ``normals`` (n,
        3): the circle fits'. The stage-1 normals' 48 neighbors turn too little at a leading
        edge, and the refined normals of a plate's rim mostly do not fan out (rims of the
        bench's plate: 18 of 55 points passed :func:`wraps` with them, 55 with these)."""
        at = np.unique(indices)
        at = at[~done[at]].astype(np.int64)
        if at.size == 0:
            return
        k = min(EDGE_NORMAL_K + 1, self.points.shape[0])
        _, nbr, _ = knn_csr(self.points, self.tree, at, k)
        out = np.empty((at.shape[0], 3))
        pca_normals(self.points, at, *_prefix_csr(nbr.reshape(-1, k)[:, 1:], k - 1), out)
        out[self.outliers[at]] = np.nan  # an outlier's normal says nothing of the surface
        normals[at] = out
        done[at] = True

    def _store_rounded_edges(self, res, edges, rows) -> None:
        """Write the reads of :meth:`_rounded_edges` at the points of ``rows`` into ``res``."""
        keep = np.isin(edges[0], rows)
        self.edge_read[edges[0][keep]] = True
        r, k1, k2, normals, dir1, dir2, s1, s2, count, reach = (x[keep] for x in edges)
        # The anchored fit stays where it agrees with the circle (its curvatures turned to the
        # circle's normal): a leading edge of 2.6 spacings, which the long ridge rung reads.
        flip = np.einsum("ij,ij->i", res.normals[r], normals) < 0.0
        a1 = np.where(flip, -res.k2[r], res.k1[r])
        a2 = np.where(flip, -res.k1[r], res.k2[r])
        with np.errstate(invalid="ignore"):
            agree = ((np.abs(a1 - k1) <= EDGE_KEEP * s1) & (np.abs(a2 - k2) <= EDGE_KEEP * s2)
                     & (res.status[r] == Status.OK))
        new = ~agree
        r, k1, k2, normals, dir1, dir2, s1, s2, count, reach = (
            x[new] for x in (r, k1, k2, normals, dir1, dir2, s1, s2, count, reach))
        res.k1[r], res.k2[r] = k1, k2
        res.normals[r], res.dir1[r], res.dir2[r] = normals, dir1, dir2
        res.status[r] = Status.OK
        res.neighbor_count[r] = count
        scale = 1.0 / self.plan.spacing
        res.k1_std[r] = with_floor(s1, k1, k2, scale)
        res.k2_std[r] = with_floor(s2, k1, k2, scale)
        res.mean_std[r] = ANCHORED_MEAN_SHARE * np.maximum(res.k1_std[r], res.k2_std[r])
        if self.track_reach:
            self.reach[r] = np.fmax(self.reach[r], reach)

    def _zone_anchors(self, reps, used):
        """The anchors ``used`` and every anchor within :data:`REFIT_ZONE` cells of one,
        increasing (indices into ``reps``)."""
        anchor_pts = self.points[reps]
        near = cKDTree(anchor_pts).query_ball_point(anchor_pts[used], REFIT_ZONE * self.plan.cell,
                                                    workers=numba.get_num_threads())
        return np.unique(np.concatenate([used] + [np.asarray(x, np.int64) for x in near]))

    def _refit_zone(self, reps, chosen, fit_reach):
        """Anchors within :data:`REFIT_ZONE` cells of one that kept a fit over at most
        :data:`REFIT_BELOW` neighbors (:meth:`_near`)."""
        return self._near(reps, chosen <= REFIT_BELOW, REFIT_ZONE * self.plan.cell, fit_reach)

    def _near(self, reps, small, radius, fit_reach):
        """Anchors within ``radius`` of one of the ``small`` anchors.

        Parameters
        ----------
        reps : ndarray, shape (a,), int64
        small : ndarray, shape (a,), bool
        radius : float
        fit_reach : ndarray, shape (a,) or None
            With ``track_reach``, how far the fit that made each anchor ``small`` or not
            depends.

        Returns
        -------
        near : ndarray, shape (a,), bool
            ``small`` itself included.
        near_reach : ndarray, shape (a,) or None
            With ``track_reach``: the largest ``distance + fit_reach`` (plus a cell diagonal,
            for which point anchors that cell) over the anchors within ``radius``, on which the
            anchor's membership depends.
        """
        near = small.copy()
        anchor_pts = self.points[reps]
        tree = cKDTree(anchor_pts)
        if small.any():
            hits = tree.query_ball_point(anchor_pts[small], radius,
                                         workers=numba.get_num_threads())
            near[np.concatenate([np.asarray(x, np.int64) for x in hits])] = True
        if fit_reach is None:
            return near, None
        pairs = tree.query_pairs(radius, output_type="ndarray")
        d = np.linalg.norm(anchor_pts[pairs[:, 0]] - anchor_pts[pairs[:, 1]], axis=1)
        near_reach = fit_reach.copy()
        lift = np.sqrt(3.0) * self.plan.cell
        np.maximum.at(near_reach, pairs[:, 0], d + fit_reach[pairs[:, 1]] + lift)
        np.maximum.at(near_reach, pairs[:, 1], d + fit_reach[pairs[:, 0]] + lift)
        return near, near_reach

    def _refit(self, res, field, field_reach, in_zone, kc):
        """Fits of their own, read at themselves, for the points of the refit zone
        (:meth:`_refit_zone`); written to ``res``.

        An anchor's model is read at every point of its cell, up to a cell diagonal (2.6
        spacings) from the anchor. Beside a large kept fit that offset is small; where the
        scale selection kept a small one (fillets, corners, leading edges, where the wider fits
        are biased) the model is read near the edge of its patch, and beside a curvature jump
        on the far side of it: on a filleted box at 0.05 % noise, corner points that read an
        anchor in the corner erred 0.46 (mean of the larger of the k1 and k2 errors), those
        that read one in the next fillet 1.63. Each such point fits the ladder up to
        :data:`REFIT_SIZE` around itself and keeps a size by the same rule (the same box's
        corners: mean |k2 error| 1.03 without the refits, 0.42 with them).

        Parameters
        ----------
        res : CurvatureResult
        field : ndarray, shape (n, 3)
            The normals the anchors' second pass fitted.
        field_reach : ndarray, shape (n,)
            How far each of those normals depends (with ``track_reach``).
        in_zone : ndarray, shape (n,), bool
            Whether each point's anchor is in the refit zone.
        kc : int

        Returns
        -------
        own : ndarray, shape (m,), int64
            The points refitted (outliers never are, nor points whose own fits all failed).
        reach : ndarray, shape (m,) or None
            With ``track_reach``, the reach of their fits.
        """
        t0 = time.perf_counter()
        own = np.flatnonzero(in_zone & ~self.outliers).astype(np.int64)
        reach = np.empty(own.shape[0]) if self.track_reach else None
        k = min(REFIT_SIZE, kc)
        self._total += own.shape[0]
        # In chunks: the fits of a chunk are read and dropped before the next is made.
        done = np.ones(own.shape[0], bool)
        for sl in self._chunks(own.shape[0]):
            query = own[sl]
            fits, fit_reach, size, err = self._fit_anchors(query, field, k, field_reach)
            out = _OutputView(res, query, 1.0 / self.plan.spacing)
            nfr_from_anchors(self.points, query, np.arange(query.shape[0], dtype=np.int64),
                             query, *fits, *out.arrays)
            # A point whose own fits all failed (a rim of 2 spacings' radius) reads its
            # anchor's model instead, like the points outside the zone.
            ok = out.arrays[6] == Status.OK
            done[sl] = ok
            out.keep(ok)
            out.store(size[ok], err[ok])
            if reach is not None:
                reach[sl] = fit_reach
            self._tick(sl.stop - sl.start)
        self.timings["refit"] = time.perf_counter() - t0
        return own[done], (reach[done] if reach is not None else None)

    def _dense(self, res, graph, rows, given=None) -> None:
        """Fits on a thinned share of a dense noisy cloud (``plan.dense``), read at ``rows``.

        The thinned points run the noisy branch as a cloud of their own, with stage-1 normals
        over as many of the whole cloud's points as the share leaves out (normal_k / share),
        so they average more points than the thinned cloud holds; each row reads the model
        of its nearest thinned point's anchor at its own position, and the rows on a rounded
        edge its circles (:meth:`_dense_edge_reads`).
        """
        n = self.points.shape[0]
        share = self.plan.dense_share
        t0 = time.perf_counter()
        idx, field, r_normal, flat = self._dense_stage1(graph, rows, given)
        self.timings["stage1"] = time.perf_counter() - t0
        sub = np.ascontiguousarray(self.points[idx])
        ns = idx.shape[0]
        params = dict(self.params, scale_gamma=self.params["scale_gamma"] * DENSE_GAMMA_SCALE)
        inner = AutoRun(sub, params, self.chunk_size, None, plan=self.plan.dense,
                        track_reach=self.track_reach)
        inner._tick = self._tick  # its work counts towards this run's progress
        inner._grow_total = self._grow_total
        # Its stage-1 normals already average normal_k / share points each, and a wide top
        # at every thinned anchor of a 10M-point cloud would cost a 1536-neighbor query each:
        # its fits stop at BASE_K.
        inner.widen = False
        inner.hash_share = share
        # Its rounded edges are looked for where the stage-1 neighborhoods (over the whole
        # cloud's points) are far from flat, as in _stage1.
        inner.edge_candidates = np.flatnonzero(worth_trying(flat, r_normal, inner._noise()))
        del flat
        reps, owner = grid_cells(sub, np.asarray(inner.plan.origin), inner.plan.cell)
        t0 = time.perf_counter()
        # Each row reads the anchor of its nearest thinned point; the second pass fits only
        # the anchors some row reads (a tile's halo holds many more).
        # (scipy's tree: queries at points that are not in the tree's cloud)
        _, nearest = cKDTree(sub).query(self.points[rows], k=1,
                                        workers=numba.get_num_threads())
        wanted, anchor_of = np.unique(owner[nearest], return_inverse=True)
        del nearest
        self.timings["dense nearest"] = time.perf_counter() - t0
        self._total += reps.shape[0] + wanted.shape[0]
        fits, fit_reach, chosen, err, _ = inner._model(field, r_normal, reps, owner,
                                                       min(inner.fit_k(), ns - 1), wanted)
        reps = reps[wanted]
        del field, r_normal, owner, wanted
        edges = self._dense_edge_reads(inner, rows, min(inner.fit_k(), ns - 1))
        self.tree = inner.tree = None  # as in _anchored: the reads need only the fits
        release_freed_memory()
        for name, sec in inner.timings.items():
            self.timings[f"dense {name}"] = sec
        t0 = time.perf_counter()
        # Thinned points first, then the cloud: one array holds anchors and readers.
        both = np.concatenate([sub, self.points])
        for sl in self._chunks(rows.shape[0]):
            query = rows[sl]
            out = _OutputView(res, query, 1.0 / self.plan.spacing)
            nfr_from_anchors(both, ns + query, anchor_of[sl], reps, *fits, *out.arrays)
            # A kept fit over s thinned points spans the patch of s / share points.
            out.store(np.rint(chosen[anchor_of[sl]] / share).astype(np.int64),
                      err[anchor_of[sl]])
            self._tick(sl.stop - sl.start)
        self.timings["dense read"] = time.perf_counter() - t0
        if self.track_reach:
            # As :meth:`_point_reach`, plus the distance to the nearest thinned point, which
            # decides the anchor; NaN at the rows not computed.
            self.reach = np.full(n, np.nan)
            d = np.linalg.norm(self.points[rows] - sub[reps[anchor_of]], axis=1)
            self.reach[rows] = 2.0 * d + fit_reach[anchor_of] + np.sqrt(3.0) * inner.plan.cell
        for reads in edges:
            if reads is not None:
                self._store_rounded_edges(res, reads, rows)

    def _dense_edge_reads(self, inner, rows, kc):
        """The rounded edges of a dense cloud (:meth:`_rounded_edges`), fitted on its thinned
        share ``inner`` (an :class:`AutoRun` over it, ``kc`` its fits' largest size) and read
        at ``rows``: the share's own circles that their point reads, within
        :data:`FILL_REACH` of their list radius (its points among the rows read their own),
        then its coarser shares' circles. Without them a dense blade's leading edge read its
        anchored fits alone (the 1,000,000-point blade at 0.25 % noise 4.2; docs/accuracy.md
        section 9, step 26).

        Returns
        -------
        own, coarse : tuple or None
            The reads as :meth:`_rounded_edges` returns them (points index this cloud).
        """
        t0 = time.perf_counter()
        n, ns = self.points.shape[0], inner.points.shape[0]
        noise = inner._noise()  # (this cloud's plan sees noise comparable to its spacing)
        circles = inner._edge_circles(np.arange(ns, dtype=np.int64), kc)
        taken = np.ones(n, bool)  # only the rows read
        taken[rows] = False
        own = None
        fine = None if circles is None else _read_circles(circles, circles[0], None, noise)
        if fine is not None:
            read = np.zeros(ns, bool)
            read[fine[0]] = True
            own = inner._filled_reads(circles, read, taken, self, noise)
        coarse = _joined([r for r in inner._coarse_edge_reads(kc, taken, self) if r[0].size])
        self.timings["dense rounded edges"] = time.perf_counter() - t0
        # A circle through s thinned points spans the patch of s / share points (as in _dense).
        share = self.plan.dense_share
        return tuple(None if r is None else r[:-2] + (np.rint(r[-2] / share).astype(np.int64),
                                                      r[-1]) for r in (own, coarse))

    def _dense_stage1(self, graph, rows, given=None):
        """The stage-1 work of a dense cloud: orientation graph rows at ``rows`` and, unless
        ``given`` (a tile's share of the whole cloud's :func:`dense_stage1`), the thinned
        points' normals and outlier tests (:func:`dense_stage1`).

        Returns
        -------
        idx : ndarray, shape (s,), int64
            The thinned points that are no outliers.
        field, r_normal, flat : ndarray, shapes (s, 3), (s,) and (s,)
            Their normals, the distance to the last neighbor behind each and how far from a
            plane those neighbors lie.
        """
        self._total = (2 if graph is not None else 1) * rows.shape[0]
        if graph is not None:
            neighbor_rows(self.points, self.tree, graph, self.chunk_size, rows, self._tick)
        if given is None:
            cand = thinned_points(self.points, self.plan.dense_share)
            self._total += cand.shape[0]
            given = whole_dense_stage1(self.points, self.tree, self.plan, self.params,
                                       self.chunk_size, self._tick, cand)
        cand, field, r_normal, outlier, flat = given
        self.outliers[cand[outlier]] = True
        keep = ~outlier
        return cand[keep], field[keep], r_normal[keep], flat[keep]

    def _model(self, field, r_normal, reps, owner, kc, wanted=None):
        """The anchors' fits of both passes: the first refines the normals (in ``field``;
        refined once more away from features, :meth:`_refine_again`), the second fits them;
        returns the second pass's fits, their reach, sizes and standard errors
        (:meth:`_fit_anchors`), and how far each refined normal depends (the reach of the
        refinements with ``track_reach``, else ``r_normal``). ``wanted`` (indices into
        ``reps``), if given, limits the second pass to those anchors, in that order."""
        # How far the first pass's normal of each point depends on: its anchor's fit reads
        # stage-1 normals of the anchor's neighbors, each made from their own neighbors.
        w = r_normal
        t0 = time.perf_counter()
        # Pass 1 only refines normals: Monge rungs would tilt them by their noisy curvature
        # over a cell's width, so its ladder has the normal-fit rungs only.
        fits, fit_reach, chosen, _ = self._fit_anchors(
            reps, field, kc, w, positional=False, positions=self._pass1_positions(reps))
        # Refined normals of every point: the first pass's field at the point; the outliers
        # stay out (a normal given at an off-surface position would bend the second pass's
        # fits towards it).
        field = self._refined_field(field, reps, owner, fits)
        field[self.outliers] = np.nan
        del fits
        if self.track_reach:
            w = self._point_reach(reps, owner, fit_reach)
        release_freed_memory()  # the pass's neighbor lists and scratch
        self.timings["pass1"] = self.timings.get("pass1", 0.0) + time.perf_counter() - t0
        t0 = time.perf_counter()
        w, again = self._refine_again(field, w, reps, owner, kc, chosen, fit_reach)
        release_freed_memory()
        self.timings["refine again"] = (self.timings.get("refine again", 0.0)
                                        + time.perf_counter() - t0)
        t0 = time.perf_counter()
        # The second pass's calibrated sigma reads its points' distances, which the normals'
        # second refinement does not change; its error does fall (REFINED_AGAIN_SIGMA).
        share = np.where(again, REFINED_AGAIN_SIGMA, 1.0)
        fits, fit_reach, chosen, err = self._fit_anchors(
            reps if wanted is None else reps[wanted], field, kc, w,
            sigma_share=share if wanted is None else share[wanted])
        release_freed_memory()
        self.timings["pass2"] = self.timings.get("pass2", 0.0) + time.perf_counter() - t0
        return fits, fit_reach, chosen, err, w

    def _refine_again(self, field, w, reps, owner, kc, chosen, fit_reach):
        """Refine the first pass's normals once more, in ``field``, at the points whose
        anchor lies farther than :data:`REFINE_AGAIN_ZONE` cells from every anchor whose
        first-pass fit kept fewer than :data:`REFINE_AGAIN_FROM` neighbors: a refine pass over
        the refined normals, read at those points. Like the first pass it reads the border's
        normals at their stage-1 centroids (:meth:`_pass1_positions`): read at the points,
        the band of a Bezier patch within 0.05-0.1 of its border errs more (10,000 points at
        0.1 % view noise, ratio to the best CGAL jet, measured with the zone around fits
        below 192: 0.54 instead of 0.48). The second pass is better read at the points (at
        the centroids: 0.54 at 0.1 %, 0.59 at 0.3 %).

        Parameters
        ----------
        field : ndarray, shape (n, 3)
            The first pass's normals (refined in place; outliers stay NaN).
        w : ndarray, shape (n,)
            How far each of them depends (with ``track_reach``; else unused).
        reps, owner : ndarray, shapes (a,) and (n,), int64
        kc : int
        chosen : ndarray, shape (a,), int64
            Neighbors of each anchor's first-pass fit.
        fit_reach : ndarray, shape (a,) or None
            Their reach (with ``track_reach``).

        Returns
        -------
        reach : ndarray, shape (n,)
            How far each normal of ``field`` now depends (``w`` without ``track_reach``).
        again : ndarray, shape (a,), bool
            The anchors refined again.
        """
        near, near_reach = self._near(reps, chosen < REFINE_AGAIN_FROM,
                                      REFINE_AGAIN_ZONE * self.plan.cell, fit_reach)
        again = np.flatnonzero(~near)
        self._grow_total(again.shape[0])
        local = np.full(reps.shape[0], -1, np.int64)
        local[again] = np.arange(again.shape[0])
        rows = np.flatnonzero(local[owner] >= 0).astype(np.int64)
        again_reach = None
        if again.size:
            fits, again_reach, _, _ = self._fit_anchors(
                reps[again], field, kc, w, positional=False,
                positions=self._pass1_positions(reps))
            self._refined_field(field, reps[again], local[owner], fits, rows)
            field[self.outliers] = np.nan
        if not self.track_reach:
            return w, ~near
        # Every point's normal depends on whether its anchor was refined again, and, if it was,
        # on that fit.
        reach = near_reach.copy()
        if again.size:
            reach[again] = np.maximum(reach[again], again_reach)
        return self._point_reach(reps, owner, reach), ~near

    def _pass1_positions(self, reps):
        """Where the first pass reads each stage-1 normal: the points, with the border's
        normals moved to their neighborhoods' centroids (:mod:`curvature.fitting.border_shift`;
        None where none moves). The anchors stay: each fit's coordinates, and the reading of
        its model at every point of the cell, are taken from the anchor's own position."""
        moved = ~np.isin(self.shift_rows, reps)
        if not moved.any():
            return None
        positions = self.points.copy()
        positions[self.shift_rows[moved]] += self.shifts[moved]
        return positions

    def _fallback(self, res, field, r_normal, reps, owner, k, failed) -> None:
        """One anchored pass over ``k`` neighbors on the stage-1 normals, for failed points.

        One pass keeps each point's result a function of its own cell only, so it does not
        depend on which other points failed (tiles see different ones).
        """
        used = np.unique(owner[failed])
        local = np.full(reps.shape[0], -1, np.int64)
        local[used] = np.arange(used.shape[0])
        fits, fit_reach, chosen, err = self._fit_anchors(
            reps[used], field, min(k, self.points.shape[0] - 1), r_normal)
        out = _OutputView(res, failed.astype(np.int64), 1.0 / self.plan.spacing)
        nfr_from_anchors(self.points, failed.astype(np.int64), local[owner[failed]], reps[used],
                         *fits, *out.arrays)
        out.store(chosen[local[owner[failed]]], err[local[owner[failed]]])
        if self.track_reach:
            full = np.zeros(reps.shape[0])
            full[used] = fit_reach
            self.reach[failed] = self._point_reach(reps, owner, full)[failed]

    def _point_reach(self, reps, owner, fit_reach) -> np.ndarray:
        """Reach of each point's anchored result: its anchor's fit, plus the anchor's distance,
        plus its cell's diagonal (every point of its cell decides which point anchors it)."""
        d = np.linalg.norm(self.points - self.points[reps[owner]], axis=1)
        return d + fit_reach[owner] + np.sqrt(3.0) * self.plan.cell

    def _fit_anchors(self, anchors, field, k, w, positional: bool = True, positions=None,
                     sigma_share=None, drop=None):
        """Fits at ``anchors`` over up to ``k`` neighbors, the size chosen per anchor
        (:mod:`curvature.fitting.scale_selection`; every anchor uses ``k`` when
        ``scale_gamma`` is 0). ``positional`` includes the Monge rungs of the ladder;
        ``positions`` (n, 3), if given, are where the normal fits read each point's normal
        (neighbors are still found at the points). ``sigma_share`` (a,), if given, scales
        each anchor's calibrated sigma in the standard errors returned (not in the selection).
        ``drop`` (n,) bool, if given, marks points left out of every list (the anchor stays).

        Returns
        -------
        fits : tuple
            The arrays :func:`~curvature.fitting.normal_field.nfr_from_anchors` reads.
        reach : ndarray, shape (a,), or None
            With ``track_reach``: the largest ``distance + w[q]`` over the anchor and its
            ``k`` neighbors q (the chosen fit uses a subset of them).
        chosen : ndarray, shape (a,), int64
            Neighbors of each anchor's kept fit.
        err : ndarray, shape (a, 2)
            Standard errors of the kept fit's k1 and k2: its calibrated noise error and the
            bias the smaller fits show in each, combined (inf where no fit was usable).
        """
        a = anchors.shape[0]
        coef = np.empty((a, 2, N_TERMS))
        scale, resid = np.empty(a), np.empty(a)
        frame = np.empty((a, 3, 3))
        quad, quad_scale = np.empty((a, N_QUAD)), np.empty(a)
        model = np.empty(a, np.int8)
        status = np.empty(a, np.int8)
        reach = np.empty(a) if self.track_reach else None
        chosen = np.full(a, k, np.int64)
        sigma, bias = np.empty(a), np.empty((a, 2))
        longer = np.zeros(a, bool)
        gamma = self.params["scale_gamma"]
        ladder, kinds, tops, strides, calib = scale_selection.pass_rungs(
            k, "fit" if positional else "refine", self.share_k())
        if gamma == 0.0:  # no ladder: every anchor keeps its fit over k neighbors
            ladder, kinds, calib = ladder[:0], kinds[:0], calib[-1:]
            tops, strides = tops[-1:], strides[-1:]
        # A ridge rung picks its patch from RIDGE_POOL neighbors (a refit's k is 192): the
        # lists are that long where the ladder has one; the other rungs and the tops use their
        # first k.
        listed = k
        if (kinds == scale_selection.KIND_MONGE_RIDGE).any():
            listed = min(max(k, RIDGE_POOL), self.points.shape[0] - 1)
        outputs = (coef, scale, frame, quad, quad_scale, model, resid, status, chosen, sigma,
                   bias, longer)
        fit = (ladder, kinds, tops, strides, gamma, calib, w, positions, field)
        self._fit_lists(anchors, None, listed, fit, outputs, reach, drop, positional)
        # The anchors beside a tight ridge fit again from the long ridge rung's pool (bun000,
        # no normals given: 956 of 45,814 fits, 0.05 s of 1.4).
        again = np.flatnonzero(longer)
        if again.size:
            self._grow_total(again.size)
            listed = min(max(k, scale_selection.RIDGE_LONG_POOL), self.points.shape[0] - 1)
            self._fit_lists(anchors, again, listed, fit, outputs, reach, drop, positional)
        if sigma_share is not None:
            sigma = sigma * sigma_share
        # The kept fit's scale: the quadric's unit where it (or a rung) was kept.
        h = np.where(model == MODEL_QUADRIC, quad_scale, scale)
        noise = self._noise()
        err = anchored_std(sigma, bias, resid, h, noise,
                           self._sheets(anchors, field, resid, noise, k))
        return (coef, scale, frame, quad, quad_scale, model, resid, status), reach, chosen, err

    def _sheets(self, anchors, field, resid, noise, k):
        """Which anchors' fits lie over two parallel sheets of a thin wall
        (:func:`~curvature.fitting.parallel_sheets.parallel_sheets` over at most ``k``, the
        fits' own neighbor count, so it reaches no farther than they do), shape (a,), bool;
        tested only where the fit's distance ``resid`` exceeds :data:`SHEET_DISTANCE` times
        the cloud's ``noise`` (elsewhere nothing would change)."""
        out = np.zeros(anchors.shape[0], bool)
        if not np.isfinite(noise):
            return out
        rows = np.flatnonzero(resid > SHEET_DISTANCE * noise)
        k = min(SHEET_K, k, self.points.shape[0] - 1)
        step = max(64, self.chunk_size * 24 // k)
        for start in range(0, rows.shape[0], step):
            at = rows[start:start + step]
            query = anchors[at]
            indptr, indices, _ = knn_csr(self.points, self.tree, query, k)
            found = np.zeros(at.shape[0], bool)
            parallel_sheets(self.points, query, np.ascontiguousarray(field[query]), indptr,
                            indices, found)
            out[at] = found
        return out

    def _fit_lists(self, anchors, rows, listed, fit, outputs, reach, drop=None,
                   own_sheet=True) -> None:
        """:func:`~curvature.fitting.scale_selection.multiscale_anchor_fits` at
        ``anchors[rows]`` (every anchor where ``rows`` is None) from lists of ``listed``
        neighbors (without the points ``drop`` marks, if given; with ``own_sheet``, on a thin
        wall's one face, :meth:`_own_sheet`), into ``outputs[...][rows]`` (and
        ``reach[rows]``), in chunks of about as many neighbor entries as a chunk of
        24-neighbor queries."""
        ladder, kinds, tops, strides, gamma, calib, w, positions, field = fit
        step = max(64, self.chunk_size * 24 // max(listed, 24))
        count = anchors.shape[0] if rows is None else rows.shape[0]
        for start in range(0, count, step):
            # (views of the outputs for every anchor; copies written back for some)
            at = slice(start, min(start + step, count)) if rows is None else \
                rows[start:start + step]
            query = anchors[at]
            indptr, indices, d2 = knn_csr(self.points, self.tree, query, listed)
            if reach is not None:
                nbr = indices.reshape(-1, listed)
                reach[at] = np.maximum((np.sqrt(d2) + w[nbr]).max(axis=1), w[query])
            if drop is not None:
                indptr, indices = without(indptr, indices, drop)
            if own_sheet:
                indptr, indices = self._own_sheet(query, field, indptr, indices)
            parts = [out[at] for out in outputs]
            multiscale_anchor_fits(self.points if positions is None else positions, field,
                                   query, indptr, indices,
                                   self.params["nfr_ratio"], ladder, kinds, tops, strides,
                                   gamma, scale_selection.SIGMA_GROWTH, calib,
                                   side_limit(self.params, self.plan, self.widen), *parts,
                                   self.turn_normals)
            if rows is not None:
                for out, part in zip(outputs, parts, strict=True):
                    out[at] = part
            self._tick(query.shape[0])

    def _own_sheet(self, query, field, indptr, indices):
        """The CSR lists of ``query`` with, at the points whose stage-1 normal was read over
        one side of a thin wall, the wall's other face left out where the list holds two
        parallel sheets, or two sheets of any slope where it lies behind its point (by the
        wall's open border; :func:`~curvature.fitting.parallel_sheets.own_sheet_lists`,
        split by ``field``'s normal at the anchor).

        Beside a thin wall's open border the two faces' points fill a list unevenly, and a
        fit over both read the border as a rounded rim: on the thin plate's faces within a
        spacing of the cut the mean error was 1.8 and depended on where the anchor grid
        fell (docs/accuracy.md, section 9, step 41); the blade's sides by its open ends
        read k2 of -20 to -40 where its wedge's faces were kept (step 42). Only the
        curvature fits (pass 2 and the refits) keep to one face: the first pass's normal
        refinement over one face refined the 10,000-point plate's normals worse (its faces
        then erred 0.39, 0.25 with both).
        """
        test = self.sided[query]
        if not test.any():
            return indptr, indices
        keep = np.empty(indices.shape[0], bool)
        own_sheet_lists(self.points, query, field, indptr, indices, test, self.outliers, keep)
        return select_entries(indptr, indices, keep)

    def _refined_field(self, field, anchors, owner, fits, rows=None):
        """First-pass normals at every point (or at ``rows``, increasing int64), computed in
        chunks and written into ``field`` (which keeps its normal where the read failed);
        ``owner[rows]`` indexes ``anchors``. The reads use only the fits, so refining in
        place changes nothing and holds one field instead of two."""
        if rows is None:
            rows = np.arange(self.points.shape[0], dtype=np.int64)
        for sl in self._chunks(rows.shape[0]):
            query = rows[sl]
            m = query.shape[0]
            outs = [np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)),
                    np.empty((m, 3)), np.empty(m), np.empty(m, np.int8)]
            nfr_from_anchors(self.points, query, owner[query], anchors, *fits, *outs)
            ok = outs[6] == Status.OK
            field[query[ok]] = outs[2][ok]
        return field


def _within_any(found: np.ndarray, reach: float, points: np.ndarray) -> np.ndarray:
    """Whether each of ``points`` (m, 3) lies within ``reach`` of one of ``found`` (f, 3),
    shape (m,), bool."""
    if found.shape[0] == 0:
        return np.zeros(points.shape[0], bool)
    d, _ = cKDTree(found).query(points, workers=numba.get_num_threads(),
                                distance_upper_bound=reach)
    return d <= reach


def _joined(reads):
    """The read tuples of ``reads`` (as :meth:`AutoRun._rounded_edges` returns them) that are
    not None, joined row-wise; None where all are."""
    parts = [r for r in reads if r is not None]
    if not parts:
        return None
    return tuple(np.concatenate(x) for x in zip(*parts, strict=True))


def _read_circles(circles: tuple, readers: np.ndarray, offsets, noise: float):
    """The reads of ``circles`` (as :meth:`AutoRun._edge_circles` returns them, one row per
    reader) at the points ``readers`` (m,), ``offsets`` (m, 3) from the points the circles
    were fitted around (None: the readers are those points), where they lie on their circle
    (:func:`~curvature.fitting.rounded_edge.read_edge_circles`). None where none does, else
    (points, k1, k2, normals, dir1, dir2, k1's and k2's standard errors, inliers, reach)."""
    _, frame, circle, curv, std, arc, count, radius = circles
    m = readers.shape[0]
    if offsets is None:
        offsets = np.zeros((m, 3))
    k1, k2, s1, s2 = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    dirs = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    read = np.zeros(m, bool)
    read_edge_circles(noise, offsets, frame, circle, curv, std, arc, k1, k2, *dirs, s1, s2, read)
    if not read.any():
        return None
    reach = radius + np.linalg.norm(offsets, axis=1)
    return (readers[read], k1[read], k2[read], *(d[read] for d in dirs), s1[read], s2[read],
            count[read], reach[read])


def _prefix_csr(nbr: np.ndarray, k: int):
    """CSR arrays of the first ``k`` columns of a (m, K) neighbor table."""
    m = nbr.shape[0]
    return (np.arange(0, (m + 1) * k, k, dtype=np.int64),
            np.ascontiguousarray(nbr[:, :k]).ravel())


def _outputs(res, sl: slice) -> tuple:
    """The output arrays of ``fit_batch`` as views of a result's rows ``sl``."""
    return (res.k1[sl], res.k2[sl], res.normals[sl], res.dir1[sl], res.dir2[sl],
            res.residual[sl], res.status[sl])


class _OutputView:
    """Scratch outputs for scattered query rows, copied into the result by :meth:`store`."""

    def __init__(self, res, rows: np.ndarray, floor_scale: float = 0.0):
        m = rows.shape[0]
        self.res = res
        self.floor_scale = floor_scale  # 1 / spacing: the rounding floor of the errors
        self.rows = rows
        self.arrays = (np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)),
                       np.empty((m, 3)), np.empty(m), np.empty(m, np.int8))

    def keep(self, mask: np.ndarray) -> None:
        """Drop the rows where ``mask`` (m,) is False: :meth:`store` leaves them untouched."""
        if not mask.all():
            self.rows = self.rows[mask]
            self.arrays = tuple(a[mask] for a in self.arrays)

    def store(self, neighbor_count, std=None) -> None:
        """Copy the rows into the result; ``std`` (m, 2) holds the standard errors of their
        k1 and k2 (the rows keep theirs when not given); H's is a share of the larger."""
        r = self.rows
        k1, k2, normals, dir1, dir2, residual, status = self.arrays
        self.res.k1[r], self.res.k2[r], self.res.residual[r], self.res.status[r] = \
            k1, k2, residual, status
        self.res.normals[r], self.res.dir1[r], self.res.dir2[r] = normals, dir1, dir2
        self.res.neighbor_count[r] = neighbor_count
        if std is not None:
            ok = status == Status.OK
            std1 = with_floor(np.where(ok, std[:, 0], np.nan), k1, k2, self.floor_scale)
            std2 = with_floor(np.where(ok, std[:, 1], np.nan), k1, k2, self.floor_scale)
            self.res.k1_std[r] = std1
            self.res.k2_std[r] = std2
            self.res.mean_std[r] = ANCHORED_MEAN_SHARE * np.maximum(std1, std2)


__all__ = ["AUTO_PARAMS", "AutoPlan", "AutoRun", "grid_cells", "largest_fit", "plan_auto",
           "plan_sample", "wide_fits"]
