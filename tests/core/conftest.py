"""Fixtures shared by the core tests."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from curvature.estimators import auto


@pytest.fixture
def move_anchor_grid(monkeypatch):
    """A function that moves the default estimator's anchor grid: its corner goes back by
    ``cells`` (3,) grid cells for the rest of the test (results must not hang on where the
    grid falls)."""
    plan_auto = auto.plan_auto

    def move(cells):
        def moved(*args, **kwargs):
            plan = plan_auto(*args, **kwargs)
            corner = np.asarray(plan.origin) - np.asarray(cells, float) * plan.cell
            return dataclasses.replace(plan, origin=tuple(float(v) for v in corner))

        monkeypatch.setattr(auto, "plan_auto", moved)

    return move
