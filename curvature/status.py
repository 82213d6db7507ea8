"""Per-point status codes (DESIGN.md section 3)."""

from __future__ import annotations

from enum import IntEnum


class Status(IntEnum):
    """Why a point has no curvature. Curvature fields are NaN wherever status != OK."""

    OK = 0
    TOO_FEW_NEIGHBORS = 1
    DEGENERATE_FIT = 2
    NO_FOOT_POINT = 3
    NON_FINITE = 4


STATUS_NAMES = {s.value: s.name.lower() for s in Status}
