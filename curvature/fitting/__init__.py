"""Fit models (DESIGN.md 4.5): the paper's general implicit quadric and the Monge height."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..neighborhoods.base import Neighborhoods
from ..params import ParamSpec, resolve_params
from .kernels import FIT_IMPLICIT, FIT_MONGE, SOLVER_ALGEBRAIC, SOLVER_TAUBIN, fit_batch
from .normal_field import nfr_batch, pca_normals

FITS = ("implicit", "monge", "nfr")
SOLVERS = ("taubin", "algebraic")
FIT_PARAMS = (
    ParamSpec("solver", str, "taubin", help="implicit quadric solver: Taubin (default) or "
              "algebraic (unit coefficient norm)", choices=SOLVERS),
    ParamSpec("include_self", bool, True, help="include the query point itself in its fit"),
    ParamSpec("normal_k", int, 48, 6, 1024,
              help="fit 'nfr' only: neighbors of the stage-1 PCA normals"),
)
# Parameters that belong to one fit model only.
FIT_ONLY = {"solver": "implicit", "normal_k": "nfr"}


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
    for name, owner in FIT_ONLY.items():
        if params.get(name) is not None and fit != owner:
            raise ParameterError(
                f"fit '{fit}': parameter '{name}' applies to fit '{owner}' only")
    return checked


def fit_neighborhoods(points: np.ndarray, query: np.ndarray, nbhd: Neighborhoods,
                      fit: str = "implicit", solver: str = "taubin",
                      include_self: bool = True, stage1: np.ndarray | None = None) -> FitOutput:
    """Fit a quadric to every query point's neighborhood.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
        The cloud (validated, C-contiguous).
    query : ndarray, shape (m,), int64
        Query point indices.
    nbhd : Neighborhoods
        Their neighborhoods, one per query point.
    fit : {"implicit", "monge", "nfr"}
    solver : {"taubin", "algebraic"}
        Implicit quadric solver.
    include_self : bool
        Include the query point itself in its fit (DESIGN.md 4).
    stage1 : ndarray, shape (n, 3), optional
        Stage-1 normals of every point, required by fit "nfr" (see :func:`stage1_normals`).

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
        fit_batch(points, query, nbhd.indptr, nbhd.indices,
                  FIT_IMPLICIT if fit == "implicit" else FIT_MONGE,
                  SOLVER_TAUBIN if solver == "taubin" else SOLVER_ALGEBRAIC,
                  bool(include_self), *outputs)
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
