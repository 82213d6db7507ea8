"""What ``estimate`` was asked for, checked: method, fit, parameters, preset, orientation,
viewpoint, workers, chunk and tile sizes (:class:`Request`, picklable, travels with each tile).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..estimators.auto import AUTO_PARAMS
from ..fitting import FIT_PARAMS, resolve_fit
from ..neighborhoods import FINDERS
from ..params import resolve_params
from .threads import resolve_workers

ORIENTATIONS = ("auto", "normals", "viewpoint")
DEFAULT_METHOD = "auto"
# Fit of the neighborhood methods when none is named: the implicit quadric where it fits the
# neighborhood (exact on quadrics), the height function where noise would make the implicit
# one speckle (real scans); measured in docs/defaults.md.
DEFAULT_FIT = "adaptive"
#: Named configurations: ``estimate(points, preset="paper")``.
PRESETS = {
    # The paper's own setting: Territory Claiming grown to 10 neighbors from 30 candidates,
    # implicit quadric.
    "paper": {"method": "tc", "fit": "implicit", "min_neighbors": 10, "candidates": 30},
}
# Clouds above TILE_ABOVE points are processed in tiles of AUTO_TILE_POINTS (tile_points=None):
# a tile's working set is about 550 bytes per tile point, beside about 200 per cloud point.
TILE_ABOVE = 2_000_000
AUTO_TILE_POINTS = 1_000_000
# Tiles handed to an executor: small enough to spread over a cluster, large enough that the
# halo (a few spacings around the tile) stays a small share of the work.
EXECUTOR_TILE_POINTS = 250_000
MIN_TILE_POINTS = 1000


def resolve_orientation(orientation, normals, viewpoint) -> str:
    """Pick the orientation mode (DESIGN.md 5) and check that its input is present."""
    if orientation is None:
        return "normals" if normals is not None else "viewpoint" if viewpoint is not None \
            else "auto"
    if orientation not in ORIENTATIONS:
        raise ParameterError(
            f"unknown orientation {orientation!r}; choose one of {list(ORIENTATIONS)}")
    if orientation == "normals" and normals is None:
        raise ParameterError("orientation 'normals' needs per-point normals")
    if orientation == "viewpoint" and viewpoint is None:
        raise ParameterError("orientation 'viewpoint' needs a viewpoint (x, y, z)")
    return orientation


def check_viewpoint(viewpoint, n: int) -> np.ndarray | None:
    """A viewpoint as a finite float64 array: shape (3,), or (n, 3) for one per point."""
    if viewpoint is None:
        return None
    try:
        vp = np.asarray(viewpoint, np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"viewpoint must be three numbers, got {viewpoint!r}") from None
    if vp.ndim == 2 and vp.shape[1] == 3 and vp.shape[0] != 1:
        if vp.shape[0] != n:
            raise ParameterError(f"per-point viewpoints must have shape ({n}, 3) to match "
                                 f"the {n} points, got {vp.shape}")
        bad = np.flatnonzero(~np.isfinite(vp).all(axis=1))
        if bad.size:
            raise ParameterError(f"the viewpoint of point {int(bad[0])} is not finite")
        return vp
    vp = vp.reshape(-1)
    if vp.shape != (3,) or not np.isfinite(vp).all():
        raise ParameterError(f"viewpoint must be three finite numbers (or one row per point), "
                             f"got {viewpoint!r}")
    return vp


def split_params(params: dict) -> tuple[dict, dict]:
    """Separate fit parameters (solver, include_self) from neighborhood method parameters."""
    fit_names = {s.name for s in FIT_PARAMS}
    fit_params = {k: v for k, v in params.items() if k in fit_names}
    method_params = {k: v for k, v in params.items() if k not in fit_names}
    return fit_params, method_params


def apply_preset(preset, method, fit, params: dict) -> tuple[str, str | None, dict]:
    """Method, fit and parameters after a named preset; explicit arguments must agree with it.

    Parameters given beside the preset override the preset's own values.
    """
    if preset is None:
        return (DEFAULT_METHOD if method is None else method), fit, params
    if preset not in PRESETS:
        raise ParameterError(f"unknown preset {preset!r}; choose one of {sorted(PRESETS)}")
    conf = dict(PRESETS[preset])
    p_method, p_fit = conf.pop("method"), conf.pop("fit")
    for name, given, wanted in (("method", method, p_method), ("fit", fit, p_fit)):
        if given is not None and given != wanted:
            raise ParameterError(
                f"preset {preset!r} uses {name} {wanted!r}; {name} {given!r} contradicts it")
    return p_method, p_fit, {**conf, **params}


METHODS = ("auto", *FINDERS)


@dataclass(frozen=True)
class Request:
    """Everything ``estimate`` was asked for, checked (picklable: tiles travel with it)."""

    method: str
    fit: str | None
    fit_opts: dict
    method_params: dict
    auto_params: dict
    mode: str
    workers: int
    chunk_size: int


def resolve_request(preset, method, fit, params, orientation, ref_normals, viewpoint, workers,
                    chunk_size) -> Request:
    """Check method, fit, parameters, orientation, workers and chunk size."""
    method, fit, params = apply_preset(preset, method, fit, params)
    if method not in METHODS:
        raise ParameterError(f"unknown method {method!r}; choose one of {sorted(METHODS)}")
    mode = resolve_orientation(orientation, ref_normals, viewpoint)
    fit_opts, method_params, auto_params = {}, {}, {}
    if method == "auto":
        if fit is not None:
            raise ParameterError(
                f"method 'auto' chooses its own fit; fit {fit!r} needs a neighborhood method "
                f"({', '.join(sorted(FINDERS))})")
        auto_params = resolve_params(AUTO_PARAMS, params, "method 'auto'")
    else:
        fit = DEFAULT_FIT if fit is None else fit
        fit_params, method_params = split_params(params)
        fit_opts = resolve_fit(fit, fit_params)
    nthreads = resolve_workers(workers)
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or chunk_size < 1:
        raise ParameterError(f"chunk_size must be a whole number >= 1, got {chunk_size!r}")
    return Request(method, fit, fit_opts, method_params, auto_params, mode, nthreads,
                   chunk_size)


def resolve_tile_points(tile_points, n: int, executor: bool = False) -> int | None:
    """Core points per tile, or None to run the cloud as one block.

    ``None`` tiles clouds larger than :data:`TILE_ABOVE`; 0 never tiles. With an
    executor the cloud is always tiled, by default in tiles of :data:`EXECUTOR_TILE_POINTS`
    (0: one tile).
    """
    if tile_points is not None and (
            isinstance(tile_points, bool) or not isinstance(tile_points, int | np.integer)
            or tile_points < 0):
        raise ParameterError(f"tile_points must be a whole number >= 0, got {tile_points!r}")
    if executor:
        size = EXECUTOR_TILE_POINTS if tile_points is None else int(tile_points) or n
        return max(min(size, n), min(MIN_TILE_POINTS, n))
    if tile_points is None:
        return AUTO_TILE_POINTS if n > TILE_ABOVE else None
    if tile_points == 0 or tile_points >= n:
        return None
    return max(int(tile_points), MIN_TILE_POINTS)
