"""Estimators: what turns the points of a block into per-point curvature.

:mod:`~curvature.estimators.auto` (method "auto", the default) measures noise and spacing and
picks model and scale per point; :mod:`~curvature.estimators.fixed` runs one named
neighborhood method with one fit model. Both write into a :class:`curvature.CurvatureResult`
and neither knows about tiles, orientation or input order (:mod:`curvature.pipeline`).
"""
