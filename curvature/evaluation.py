"""Accuracy metrics for curvature estimates (DESIGN.md section 8).

Three measurements, all vectorized over points:

- :func:`point_errors` and :func:`error_summary`: absolute errors of k1 and k2 against exact
  values, and their mean, standard deviation, median and 90th percentile over the points that
  were estimated, with the failure count beside them.
- :func:`win_share` (the paper's eta): the share of points where method A's error is below
  method B's, on the same cloud.
- :func:`density_consistency`: how much the estimate at a point moves when part of the cloud is
  deleted (real scans, no exact values).

Failed points (``status != 0``, NaN curvature) never vanish silently: summaries count them, and
in eta a failed point loses against a successful one (see :func:`win_share`).

Examples
--------
>>> import curvature
>>> from curvature import evaluation, synthetic
>>> cloud = synthetic.torus(3000, seed=1)
>>> res = curvature.estimate(cloud.points, "knn", k=24, fit="monge", normals=cloud.normals)
>>> err = evaluation.point_errors(res, cloud.k1, cloud.k2)
>>> stats = evaluation.error_summary(err)
>>> stats["failures"], stats["k1_mean"] < 0.05
(0, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "PointErrors",
    "density_consistency",
    "error_summary",
    "point_errors",
    "win_share",
]


@dataclass(frozen=True)
class PointErrors:
    """Per-point absolute curvature errors over the evaluated points.

    Attributes
    ----------
    k1, k2 : ndarray, shape (m,), float64
        ``|k1_est - k1_true|`` and ``|k2_est - k2_true|``; NaN where the point failed.
    failed : ndarray, shape (m,), bool
        True where the estimate has ``status != 0`` (or, defensively, a non-finite value).
    """

    k1: np.ndarray
    k2: np.ndarray
    failed: np.ndarray

    def __len__(self) -> int:
        return int(self.failed.shape[0])


def point_errors(result, true_k1, true_k2, mask=None) -> PointErrors:
    """Absolute errors of a result's k1 and k2 against exact values.

    Parameters
    ----------
    result : CurvatureResult
        The estimate (``k1``, ``k2``, ``status`` per point).
    true_k1, true_k2 : array_like, shape (n,)
        Exact principal curvatures in the same sign convention (k1 >= k2).
    mask : array_like of bool, shape (n,), optional
        Points to evaluate (e.g. ``cloud.interior``); all points by default.

    Returns
    -------
    PointErrors
        Errors of the selected points, in input order.
    """
    sel = slice(None) if mask is None else np.asarray(mask, dtype=bool)
    e1 = np.abs(result.k1[sel] - np.asarray(true_k1, np.float64)[sel])
    e2 = np.abs(result.k2[sel] - np.asarray(true_k2, np.float64)[sel])
    failed = (result.status[sel] != 0) | ~np.isfinite(e1) | ~np.isfinite(e2)
    e1[failed] = np.nan
    e2[failed] = np.nan
    return PointErrors(k1=e1, k2=e2, failed=failed)


def _stats(values: np.ndarray, prefix: str) -> dict[str, float]:
    """Mean, std, median and p90 of the finite ``values`` (NaN when there are none)."""
    good = values[np.isfinite(values)]
    if good.size == 0:
        return {f"{prefix}_{s}": float("nan") for s in ("mean", "std", "median", "p90")}
    p50, p90 = np.percentile(good, [50, 90])
    return {f"{prefix}_mean": float(good.mean()), f"{prefix}_std": float(good.std()),
            f"{prefix}_median": float(p50), f"{prefix}_p90": float(p90)}


def error_summary(errors: PointErrors) -> dict[str, float | int]:
    """Statistics of the absolute errors over the successful points, and the failure count.

    Parameters
    ----------
    errors : PointErrors

    Returns
    -------
    dict
        ``points`` (evaluated), ``failures``, ``failure_rate`` (failures / points), and
        ``k1_mean``, ``k1_std``, ``k1_median``, ``k1_p90`` and the same for ``k2``. Mean and
        std are the paper's statistics; the median and p90 stay readable when the implicit
        quadric produces a few huge outliers.
    """
    m = len(errors)
    failures = int(errors.failed.sum())
    return {"points": m, "failures": failures,
            "failure_rate": failures / m if m else float("nan"),
            **_stats(errors.k1, "k1"), **_stats(errors.k2, "k2")}


def _scores(err_a: np.ndarray, err_b: np.ndarray, failed_a: np.ndarray,
            failed_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-point score of A against B (1 win, 0.5 tie, 0 loss) and the tie mask."""
    a_wins = (~failed_a & failed_b) | (~failed_a & ~failed_b & (err_a < err_b))
    tie = (failed_a & failed_b) | (~failed_a & ~failed_b & (err_a == err_b))
    return a_wins + 0.5 * tie, tie


def win_share(a: PointErrors, b: PointErrors) -> dict[str, float | int]:
    """The paper's eta: share of points where method A's error is below method B's.

    Both error sets must come from the same cloud and mask. Per point and per curvature, A
    scores 1 when its error is smaller, 0 when larger, 0.5 on an exact tie. Failures: a failed
    point loses against a successful one, and two failed points tie. So
    ``eta(A, B) + eta(B, A) == 1`` and 0.5 means "no better, no worse". Exact ties do happen
    when two methods pick the same neighbors (e.g. TC and 10-NN on a regular sampling); their
    share is reported so the strict reading (ties count 0) is ``eta - tie / 2``.

    Parameters
    ----------
    a, b : PointErrors
        Errors of method A and method B at the same points.

    Returns
    -------
    dict
        ``points``, ``eta_k1``, ``eta_k2`` (scores averaged over all points) and ``tie_k1``,
        ``tie_k2`` (share of tied points).

    Raises
    ------
    ValueError
        If the two error sets have different lengths.
    """
    if len(a) != len(b):
        raise ValueError(f"error sets differ in length: {len(a)} and {len(b)}")
    m = len(a)
    out: dict[str, float | int] = {"points": m}
    for name in ("k1", "k2"):
        score, tie = _scores(getattr(a, name), getattr(b, name), a.failed, b.failed)
        out[f"eta_{name}"] = float(score.mean()) if m else float("nan")
        out[f"tie_{name}"] = float(tie.mean()) if m else float("nan")
    return out


def density_consistency(full, reduced, kept) -> dict[str, float | int]:
    """Change of the estimate at the kept points when the rest of the cloud is deleted.

    Parameters
    ----------
    full : CurvatureResult
        Estimate on the whole cloud (n points).
    reduced : CurvatureResult
        Estimate on the reduced cloud ``points[kept]``, in the order of ``kept``.
    kept : array_like of int, shape (m,)
        Indices of the kept points in the full cloud.

    Returns
    -------
    dict
        ``kept`` (m), ``failed_full`` and ``failed_reduced`` (failures among the kept points
        in each run), ``compared`` (kept points where both succeeded), and ``dk1_median``,
        ``dk1_mean``, ``dk2_*``, ``dH_*``: median and mean of ``|k1_reduced - k1_full|``, the
        same for k2 and for the mean curvature H, over the compared points.
    """
    kept = np.asarray(kept, dtype=np.int64)
    if len(reduced) != kept.size:
        raise ValueError(f"reduced result has {len(reduced)} points, kept lists {kept.size}")
    ok_full = full.status[kept] == 0
    ok_reduced = reduced.status == 0
    both = ok_full & ok_reduced
    out: dict[str, float | int] = {
        "kept": int(kept.size), "failed_full": int((~ok_full).sum()),
        "failed_reduced": int((~ok_reduced).sum()), "compared": int(both.sum())}
    for name, attr in (("dk1", "k1"), ("dk2", "k2"), ("dH", "mean")):
        diff = np.abs(getattr(reduced, attr)[both] - getattr(full, attr)[kept[both]])
        diff = diff[np.isfinite(diff)]
        out[f"{name}_median"] = float(np.median(diff)) if diff.size else float("nan")
        out[f"{name}_mean"] = float(diff.mean()) if diff.size else float("nan")
    return out
