"""Fit models (DESIGN.md 4.5): the paper's general implicit quadric and the Monge height."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..neighborhoods.base import Neighborhoods
from ..params import ParamSpec, resolve_params
from .kernels import FIT_IMPLICIT, FIT_MONGE, SOLVER_ALGEBRAIC, SOLVER_TAUBIN, fit_batch

FITS = ("implicit", "monge")
SOLVERS = ("taubin", "algebraic")
FIT_PARAMS = (
    ParamSpec("solver", str, "taubin", help="implicit quadric solver: Taubin (default) or "
              "algebraic (unit coefficient norm)", choices=SOLVERS),
    ParamSpec("include_self", bool, True, help="include the query point itself in its fit"),
)


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
    if fit == "monge" and params.get("solver") not in (None, "taubin"):
        raise ParameterError("fit 'monge': parameter 'solver' applies to fit 'implicit' only")
    return checked


def fit_neighborhoods(points: np.ndarray, query: np.ndarray, nbhd: Neighborhoods,
                      fit: str = "implicit", solver: str = "taubin",
                      include_self: bool = True) -> FitOutput:
    """Fit a quadric to every query point's neighborhood.

    Parameters
    ----------
    points : ndarray, shape (n, 3), float64
        The cloud (validated, C-contiguous).
    query : ndarray, shape (m,), int64
        Query point indices.
    nbhd : Neighborhoods
        Their neighborhoods, one per query point.
    fit : {"implicit", "monge"}
    solver : {"taubin", "algebraic"}
        Implicit quadric solver.
    include_self : bool
        Include the query point itself in its fit (DESIGN.md 4).

    Returns
    -------
    FitOutput
        Curvature with normals of arbitrary sign.
    """
    m = len(query)
    out = FitOutput(
        k1=np.empty(m), k2=np.empty(m), normals=np.empty((m, 3)), dir1=np.empty((m, 3)),
        dir2=np.empty((m, 3)), residual=np.empty(m), status=np.empty(m, np.int8))
    fit_batch(points, np.ascontiguousarray(query, np.int64), nbhd.indptr, nbhd.indices,
              FIT_IMPLICIT if fit == "implicit" else FIT_MONGE,
              SOLVER_TAUBIN if solver == "taubin" else SOLVER_ALGEBRAIC, bool(include_self),
              out.k1, out.k2, out.normals, out.dir1, out.dir2, out.residual, out.status)
    return out


__all__ = ["FITS", "FIT_PARAMS", "SOLVERS", "FitOutput", "fit_neighborhoods", "resolve_fit"]
