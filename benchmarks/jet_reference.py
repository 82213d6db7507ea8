"""CGAL's jet fitting (degree 2, k = 96) timed as the native reference of speed.py and scale.py.

Issue 21 asks both benchmarks to print the default estimator's points per second beside CGAL's
``Monge_via_jet_fitting`` measured in the same run. The wall time covers the whole driver call
(the cloud written to the C++ process, CGAL's kd-tree built and queried, every fit, the result
read back); the one-off compile is done before any timing. Without CGAL's headers the reason
is printed instead of a ratio.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

JET_K = 96
JET_DEGREE = 2


def time_cgal_jet(points: np.ndarray, workers: int | None, repeat: int = 1
                  ) -> tuple[float | None, str]:
    """Median wall seconds of CGAL's jet fit over ``points``, or None and the reason.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    workers : int or None
        Threads of the driver (None: every core).
    repeat : int
        Timed runs; the median is returned.

    Returns
    -------
    seconds : float or None
    label : str
        What was timed, or why nothing was.
    """
    from curvature.studies.peers.cgal import (
        build_cgal_jet,
        cgal_jet_curvature,
        cgal_unavailable_reason,
    )

    reason = cgal_unavailable_reason()
    if reason:
        return None, f"CGAL jet fitting skipped: {reason}"
    build_cgal_jet()
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        cgal_jet_curvature(points, k=JET_K, degree=JET_DEGREE, workers=workers)
        runs.append(time.perf_counter() - t)
    return statistics.median(runs), f"CGAL jet fitting (degree {JET_DEGREE}, k = {JET_K})"


def ratio_line(n: int, ours_s: float, cgal_s: float | None, label: str) -> str:
    """One line: both rates and the ratio of ours to CGAL's (above 1: we are faster)."""
    if cgal_s is None:
        return label
    return (f"{label}: {cgal_s:.2f} s, {n / cgal_s:,.0f} points/s; default / CGAL rate "
            f"{cgal_s / ours_s:.2f}x")
