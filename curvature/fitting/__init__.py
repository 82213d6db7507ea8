"""Fit models (DESIGN.md 4.5): the paper's general implicit quadric and the Monge height."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..neighborhoods.base import Neighborhoods
from ..params import ParamSpec, resolve_params
from .kernels import (
    FIT_ADAPTIVE,
    FIT_IMPLICIT,
    FIT_MONGE,
    SOLVER_ALGEBRAIC,
    SOLVER_TAUBIN,
    fit_batch,
)
from .normal_field import nfr_batch, pca_normals

FITS = ("adaptive", "implicit", "monge", "nfr")
FIT_CODES = {"adaptive": FIT_ADAPTIVE, "implicit": FIT_IMPLICIT, "monge": FIT_MONGE}
SOLVERS = ("taubin", "algebraic")
FIT_PARAMS = (
    ParamSpec("solver", str, "taubin", help="implicit quadric solver: Taubin (default) or "
              "algebraic (unit coefficient norm)", choices=SOLVERS),
    ParamSpec("include_self", bool, True, help="include the query point itself in its fit"),
    ParamSpec("normal_k", int, 48, 6, 1024,
              help="fit 'nfr' only: neighbors of the stage-1 PCA normals"),
    ParamSpec("clean_residual", float, 0.01, 0.0, 1.0,
              help="fit 'adaptive' only: the implicit quadric is kept where its RMS residual "
                   "is at most this fraction of the RMS neighbor distance; elsewhere the "
                   "height function is fitted"),
)
# Parameters that belong to some fit models only.
FIT_ONLY = {"solver": ("implicit", "adaptive"), "normal_k": ("nfr",),
            "clean_residual": ("adaptive",)}


@dataclass
class FitOutput:
    """Raw per-point fit results before orientation; arrays as in CurvatureResult.

    Attributes
    ----------
    k1, k2, residual : ndarray, shape (m,)
    normals, dir1, dir2 : ndarray, shape (m, 3)
        ``normals`` are unit but of arbitrary sign.
    status : ndarray, shape (m,), int8
    """

    k1: np.ndarray
    k2: np.ndarray
    normals: np.ndarray
    dir1: np.ndarray
    dir2: np.ndarray
    residual: np.ndarray
    status: np.ndarray


def resolve_fit(fit: str, params: dict) -> dict:
    """Check the fit model name and its parameters; return the checked parameters."""
    if fit not in FITS:
        raise ParameterError(f"unknown fit {fit!r}; choose one of {list(FITS)}")
    checked = resolve_params(FIT_PARAMS, params, f"fit '{fit}'")
    for name, owners in FIT_ONLY.items():
        if params.get(name) is not None and fit not in owners:
            raise ParameterError(
                f"fit '{fit}': parameter '{name}' applies to fit "
                f"{' and '.join(repr(o) for o in owners)} only")
    return checked


def fit_neighborhoods(points: np.ndarray, query: np.ndarray, nbhd: Neighborhoods,
                      fit: str = "implicit", solver: str = "taubin",
                      include_self: bool = True, stage1: np.ndarray | None = None,
                      clean_residual: float = 0.01) -> FitOutput:
    """Fit a quadric to every query point's neighborhood.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
        The cloud (validated, C-contiguous).
    query : ndarray, shape (m,), int64
        Query point indices.
    nbhd : Neighborhoods
        Their neighborhoods, one per query point.
    fit : {"adaptive", "implicit", "monge", "nfr"}
    solver : {"taubin", "algebraic"}
        Implicit quadric solver.
    include_self : bool
        Include the query point itself in its fit (DESIGN.md 4).
    stage1 : ndarray, shape (n, 3), optional
        Stage-1 normals of every point, required by fit "nfr" (see :func:`stage1_normals`).
    clean_residual : float
        Fit "adaptive": largest RMS residual of a kept implicit quadric, as a fraction of the
        RMS neighbor distance.

    Returns
    -------
    FitOutput
        Curvature with normals of arbitrary sign.
    """
    m = len(query)
    out = FitOutput(
        k1=np.empty(m), k2=np.empty(m), normals=np.empty((m, 3)), dir1=np.empty((m, 3)),
        dir2=np.empty((m, 3)), residual=np.empty(m), status=np.empty(m, np.int8))
    query = np.ascontiguousarray(query, np.int64)
    outputs = (out.k1, out.k2, out.normals, out.dir1, out.dir2, out.residual, out.status)
    if fit == "nfr":
        if stage1 is None:
            raise ParameterError("fit 'nfr' needs stage-1 normals")
        nfr_batch(points, stage1, query, nbhd.indptr, nbhd.indices, bool(include_self),
                  *outputs)
    else:
        fit_batch(points, query, nbhd.indptr, nbhd.indices, FIT_CODES[fit],
                  SOLVER_TAUBIN if solver == "taubin" else SOLVER_ALGEBRAIC,
                  bool(include_self), float(clean_residual), *outputs)
    return out


def stage1_normals(points: np.ndarray, finder, chunk_size: int, workers: int) -> np.ndarray:
    """PCA normals (arbitrary sign) of every point over the neighborhoods of ``finder``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    finder : NeighborFinder
        Usually k nearest neighbors with ``k = normal_k``.
    chunk_size : int
        Query points per chunk (bounds memory).
    workers : int
        Threads for the neighbor search.

    Returns
    -------
    ndarray, shape (n, 3)
        NaN rows where the neighbors do not span a plane.
    """
    n = points.shape[0]
    out = np.empty((n, 3))
    for start in range(0, n, chunk_size):
        query = np.arange(start, min(start + chunk_size, n), dtype=np.int64)
        nbhd = finder.query(query, workers=workers)
        pca_normals(points, query, nbhd.indptr, nbhd.indices, out[start:start + len(query)])
    return out


__all__ = ["FITS", "FIT_ONLY", "FIT_PARAMS", "SOLVERS", "FitOutput", "fit_neighborhoods",
           "resolve_fit", "stage1_normals"]
