"""MeshLab's APSS curvature as a benchmark reference (optional, needs ``pymeshlab``).

APSS (algebraic point set surfaces; Guennebaud and Gross, SIGGRAPH 2007) fits an algebraic
sphere to the oriented points around each point and reads the curvature off the gradient and
Hessian of the fitted scalar field. MeshLab ships it as the filter "Colorize curvature (APSS)",
called ``compute_curvature_and_color_apss_per_vertex`` in pymeshlab. This module runs that
filter so benchmarks can put it side by side with our estimators. ``pymeshlab`` belongs to the
``bench`` extra (``pip install 'curvature[bench]'``) and is never a runtime dependency: it is
imported only inside the functions here.

How the filter's output maps to our convention
----------------------------------------------
The filter writes one number per vertex into the vertex quality (``vertex_scalar_array``),
chosen by ``curvaturetype``:

* ``"Mean"`` is the trace of the Weingarten map, i.e. ``k1 + k2`` (not their average: a sphere
  of radius 2 gives 1.0);
* ``"Gauss"`` is ``k1 * k2``;
* ``"K1"`` / ``"K2"`` are ordered by magnitude, not signed value, and they are NaN at umbilic
  points (a sphere), where pymeshlab 2025.7 then aborts the process while colouring
  ("double free or corruption");
* ``"ApproxMean"`` is the inverse radius of the fitted sphere.

The sign follows the input normals exactly as ours does: with outward normals a sphere of
radius r gives ``Mean = +2/r``; flipped normals give ``-2/r``. So no negation is needed. We run
``"Mean"`` and ``"Gauss"`` and solve ``k1, k2 = H +- sqrt(H**2 - K)`` with ``H = Mean / 2``
(the discriminant clamped at zero), which gives signed ``k1 >= k2`` and never hits the umbilic
crash. Points where the filter's projection or gradient failed are left at exactly 0 for both
quantities by MeshLab; they are returned as NaN.

Normals
-------
APSS needs oriented normals. Given ones are used as they are. Otherwise they are estimated by
pymeshlab's ``compute_normal_for_point_clouds`` (plane fit over ``normal_neighbors`` nearest
points; default 30, since MeshLab's own default of 10 roughly doubles the curvature errors at
0.5 % noise) and oriented by ``orientation``:

* ``"auto"`` (default): our own minimum-spanning-tree propagation
  (:func:`curvature.orientation.signs_auto`, seeded outward at the point farthest from the
  centroid), the rule of ``curvature.estimate(..., orientation="auto")``;
* ``"viewpoint"``: each normal faces ``viewpoint``;
* ``"meshlab"``: pymeshlab's own orientation, unchanged (on closed synthetic shapes it points
  mostly *inward* and leaves a fraction of a percent flipped, so curvature signs come out
  reversed: use only to study MeshLab as-is).

Timing
------
Each filter run projects every point onto the APSS surface and evaluates gradient and Hessian
there; we need two runs (Mean and Gauss) plus the normal estimation (about 0.2 s per 10,000
points with orientation). pymeshlab runs single-threaded. With ``filter_scale=8`` on the
2-core benchmark machine, 10,000 points take 1.2 to 3.4 s and 20,000 points 2.7 to 8 s
depending on load, i.e. about 12 to 35 s per 100,000 points extrapolated; a direct 100,000
point run took 34 to 150 s wall (83 s CPU) on the shared, loaded machine. The cost grows with
``filter_scale`` (about 2x at 10 and 6x at 14 relative to 8).

Examples
--------
>>> from curvature import synthetic
>>> from curvature.studies.peers.apss import apss_available, apss_curvature
>>> cloud = synthetic.sphere(2000, radius=2.0)
>>> if apss_available():  # doctest: +SKIP
...     k1, k2 = apss_curvature(cloud.points, cloud.normals)
"""

from __future__ import annotations

import importlib.util

import numpy as np
from scipy.spatial import cKDTree

from ...errors import ParameterError
from ...orientation import ORIENT_K, signs_auto, signs_from_viewpoint

__all__ = [
    "APSS_ORIENTATIONS",
    "apss_available",
    "apss_curvature",
    "estimate_normals",
    "principal_from_mean_gauss",
]

#: Ways to orient normals that :func:`estimate_normals` computes.
APSS_ORIENTATIONS = ("auto", "viewpoint", "meshlab")

_INSTALL_HINT = (
    "MeshLab's APSS reference needs pymeshlab, an optional benchmark dependency; "
    "install it with: pip install 'curvature[bench]'"
)


def apss_available() -> bool:
    """Whether ``pymeshlab`` can be imported (without importing it).

    Returns
    -------
    bool
    """
    return importlib.util.find_spec("pymeshlab") is not None


def _pymeshlab():
    """Import and return ``pymeshlab``, or raise ImportError with the install hint."""
    try:
        import pymeshlab
    except ImportError as exc:
        raise ImportError(_INSTALL_HINT) from exc
    return pymeshlab


def _as_points(points, name: str = "points") -> np.ndarray:
    """``points`` as a C-contiguous float64 (n, 3) array of finite values."""
    arr = np.ascontiguousarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ParameterError(f"{name} must have shape (n, 3), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ParameterError(f"{name} must be finite")
    return arr


def _knn_graph(points: np.ndarray, k: int) -> np.ndarray:
    """Indices of each point's ``k`` nearest other points, shape (n, k), -1 padded."""
    n = points.shape[0]
    kk = min(k + 1, n)
    _, idx = cKDTree(points).query(points, k=kk)
    idx = np.asarray(idx, dtype=np.int64).reshape(n, kk)[:, 1:]
    out = np.full((n, k), -1, np.int64)
    out[:, : idx.shape[1]] = idx
    return out


def estimate_normals(points, *, neighbors: int = 30, smooth_iters: int = 0,
                     orientation: str = "auto", viewpoint=None) -> np.ndarray:
    """Unit normals from pymeshlab's point-cloud normal filter, oriented as asked.

    Parameters
    ----------
    points : array_like, shape (n, 3)
    neighbors : int
        ``k`` of ``compute_normal_for_point_clouds`` (points in each plane fit).
    smooth_iters : int
        ``smoothiter`` of the same filter (normal smoothing passes).
    orientation : {"auto", "viewpoint", "meshlab"}
        See the module docstring.
    viewpoint : array_like, shape (3,), optional
        Required for ``orientation="viewpoint"``.

    Returns
    -------
    ndarray, shape (n, 3), float64

    Raises
    ------
    ImportError
        pymeshlab is not installed.
    ParameterError
        Bad shapes or an unknown orientation.
    """
    pts = _as_points(points)
    if orientation not in APSS_ORIENTATIONS:
        raise ParameterError(
            f"unknown orientation {orientation!r}; choose one of {list(APSS_ORIENTATIONS)}")
    if orientation == "viewpoint" and viewpoint is None:
        raise ParameterError("orientation 'viewpoint' needs a viewpoint (x, y, z)")
    pml = _pymeshlab()
    ms = pml.MeshSet()
    ms.add_mesh(pml.Mesh(vertex_matrix=pts))
    ms.compute_normal_for_point_clouds(k=int(neighbors), smoothiter=int(smooth_iters),
                                       flipflag=False, viewpos=np.zeros(3))
    normals = np.array(ms.current_mesh().vertex_normal_matrix(), dtype=np.float64)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    if orientation == "auto":
        signs = signs_auto(pts, normals, _knn_graph(pts, ORIENT_K))
    elif orientation == "viewpoint":
        signs = signs_from_viewpoint(pts, normals, viewpoint)
    else:
        return normals
    return normals * signs[:, None].astype(np.float64)


def apss_curvature(points, normals=None, filter_scale: float = 8.0, *,
                   projection_accuracy: float = 1e-4, max_projection_iters: int = 15,
                   spherical_parameter: float = 1.0, orientation: str = "auto",
                   viewpoint=None, normal_neighbors: int = 30,
                   normal_smooth_iters: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Principal curvatures by MeshLab's APSS, in this library's convention.

    Parameters
    ----------
    points : array_like, shape (n, 3)
    normals : array_like, shape (n, 3), optional
        Oriented normals; the curvature sign follows them (positive where the surface bends
        away from the normal). Estimated with :func:`estimate_normals` when omitted.
    filter_scale : float
        ``filterscale``: the APSS kernel width relative to the local point spacing (MeshLab's
        default is 2; 8 is the setting issue 6 quotes as APSS's best).
    projection_accuracy, max_projection_iters, spherical_parameter
        ``projectionaccuracy``, ``maxprojectioniters`` and ``sphericalparameter`` of the
        filter (MeshLab's defaults; 1 is a pure sphere fit, 0 a plane fit).
    orientation : {"auto", "viewpoint", "meshlab"}
        How estimated normals are oriented; ignored when ``normals`` is given.
    viewpoint : array_like, shape (3,), optional
        For ``orientation="viewpoint"``.
    normal_neighbors, normal_smooth_iters : int
        ``k`` and ``smoothiter`` of the normal estimation.

    Returns
    -------
    k1, k2 : ndarray, shape (n,), float64
        Signed principal curvatures with ``k1 >= k2``; NaN where APSS failed at a point.

    Raises
    ------
    ImportError
        pymeshlab is not installed (the message says how to install it).
    ParameterError
        Bad shapes or parameters.
    """
    pts = _as_points(points)
    if not filter_scale > 0:
        raise ParameterError(f"filter_scale must be positive, got {filter_scale}")
    if normals is None:
        nrm = estimate_normals(pts, neighbors=normal_neighbors,
                               smooth_iters=normal_smooth_iters, orientation=orientation,
                               viewpoint=viewpoint)
    else:
        nrm = _as_points(normals, "normals")
        if nrm.shape != pts.shape:
            raise ParameterError(f"normals must have shape {pts.shape}, got {nrm.shape}")
    pml = _pymeshlab()
    ms = pml.MeshSet()
    ms.add_mesh(pml.Mesh(vertex_matrix=pts, v_normals_matrix=nrm))
    params = dict(filterscale=float(filter_scale), projectionaccuracy=float(projection_accuracy),
                  maxprojectioniters=int(max_projection_iters),
                  sphericalparameter=float(spherical_parameter))
    quality = {}
    for kind in ("Mean", "Gauss"):
        ms.compute_curvature_and_color_apss_per_vertex(curvaturetype=kind, **params)
        quality[kind] = np.array(ms.current_mesh().vertex_scalar_array(), dtype=np.float64)
    return principal_from_mean_gauss(quality["Mean"], quality["Gauss"])


def principal_from_mean_gauss(trace: np.ndarray, gauss: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray]:
    """Signed ``k1 >= k2`` from APSS's ``Mean`` (= k1 + k2) and ``Gauss`` (= k1 k2).

    Parameters
    ----------
    trace, gauss : ndarray, shape (n,)
        The two filter outputs; points where both are exactly 0 (MeshLab's value when the
        projection or gradient failed) become NaN.

    Returns
    -------
    k1, k2 : ndarray, shape (n,), float64
    """
    h = 0.5 * np.asarray(trace, dtype=np.float64)
    g = np.asarray(gauss, dtype=np.float64)
    root = np.sqrt(np.maximum(h * h - g, 0.0))
    k1 = h + root
    k2 = h - root
    failed = (h == 0.0) & (g == 0.0)
    k1[failed] = np.nan
    k2[failed] = np.nan
    return k1, k2
