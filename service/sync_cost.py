"""Cost bound of synchronous requests: parameters whose work explodes are refused up front.

A synchronous answer holds a worker and a client connection, so besides its time limit it gets
a budget of work units, estimated from the point count and the method's parameters before
anything runs. A unit is one candidate-pair test (Territory Claiming, Elliptic Gabriel Graph)
or one neighbor gathered and fitted (k-NN, auto, mesh rings); the estimate is coarse but grows
the way the real cost grows (candidates squared, times the beta or alpha steps, times the
rounds that ``min_neighbors`` forces), which is what lets a 1000-candidate EGG request through
the schema's bounds but not through this one.
"""

from __future__ import annotations

import math

# Neighbors a Territory Claiming round keeps, roughly; min_neighbors above it adds rounds.
_TC_KEPT_PER_ROUND = 6


def _steps(start: float, stop: float, step: float) -> int:
    """Values of ``start, start + step, ... <= stop`` (at least one)."""
    if step <= 0 or stop < start:
        return 1
    return int(math.floor((stop - start) / step + 1e-9)) + 1


def cost_per_point(params: dict) -> float:
    """Work units per point of the method and parameters in ``params`` (JSON form)."""
    method = params.get("method")
    if method == "tc":
        rounds = max(1, math.ceil(params["min_neighbors"] / _TC_KEPT_PER_ROUND))
        betas = _steps(params["beta_min"], params["beta_max"], params["beta_step"])
        return params["candidates"] ** 2 * betas * rounds
    if method == "egg":
        # alpha is lowered from alpha_start by alpha_step, at most down to alpha_step.
        alphas = max(1, math.floor(params["alpha_start"] / params["alpha_step"] + 1e-9))
        return params["candidates"] ** 2 * alphas * max(1, params["min_neighbors"] / 10)
    if method == "mesh":
        return params["k_delaunay"] ** 2 + params["min_neighbors"] ** 2
    if method == "knn":
        return params["k"]
    if method == "auto":
        return 2 * params["k"] + params["normal_k"]  # two passes plus the normals
    return 0.0


def sync_cost_problem(params: dict, n_points: int, budget: float) -> str | None:
    """Why a synchronous request is refused for its cost, or ``None`` when it fits.

    Parameters
    ----------
    params : dict
        Validated parameters (JSON form, defaults filled in).
    n_points : int
        Points of the cloud.
    budget : float
        ``CURVATURE_SYNC_MAX_COST`` work units.
    """
    cost = cost_per_point(params) * n_points
    if cost <= budget:
        return None
    return (f"method '{params.get('method')}' with these parameters on {n_points} points costs "
            f"about {cost:.3g} work units; synchronous answers are limited to {budget:.3g} "
            "(CURVATURE_SYNC_MAX_COST): lower candidates, min_neighbors or k, or submit it "
            "to POST /v1/jobs")
