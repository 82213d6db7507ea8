"""How many threads a run uses, and numba's thread count while it runs."""

from __future__ import annotations

import os
from contextlib import contextmanager

import numba
import numpy as np

from ..errors import ParameterError


def resolve_workers(workers) -> int:
    """Number of threads to use: ``None`` means every core numba may use."""
    limit = numba.config.NUMBA_NUM_THREADS
    if workers is None:
        return max(1, min(limit, os.cpu_count() or 1))
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise ParameterError(f"workers must be a whole number >= 1, got {workers!r}")
    return int(min(workers, limit))


@contextmanager
def numba_threads(count: int):
    """Run numba's parallel loops with ``count`` threads, restoring the previous count."""
    before = numba.get_num_threads()
    numba.set_num_threads(count)
    try:
        yield
    finally:
        numba.set_num_threads(before)
