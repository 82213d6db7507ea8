"""Per-point curvature of noisy 3D scans by local quadric fitting.

Public surface (DESIGN.md section 5)::

    import curvature
    res = curvature.estimate(points)                  # method "auto": model and scale measured
    res = curvature.estimate(points, preset="paper")  # the paper's TC + implicit quadric
    cloud = curvature.read("scan.ply")
    curvature.write("out.ply", res)
"""

from . import synthetic
from .auto import AUTO_PARAMS
from .cloud import PointCloud
from .errors import (
    CurvatureInputError,
    FormatError,
    NonFiniteError,
    ParameterError,
    TooFewPointsError,
    UnknownFormatError,
)
from .fitting import FIT_PARAMS
from .io import read, write
from .neighborhoods import FINDERS, Neighborhoods, neighbors
from .params import ParamSpec
from .pipeline import DEFAULT_FIT, DEFAULT_METHOD, FITS, METHODS, ORIENTATIONS, PRESETS, estimate
from .preview import FIELDS as PREVIEW_FIELDS
from .preview import VIEWS as PREVIEW_VIEWS
from .preview import render_preview
from .result import CurvatureResult
from .status import Status

__version__ = "0.1.0"

__all__ = [
    "AUTO_PARAMS",
    "DEFAULT_FIT",
    "DEFAULT_METHOD",
    "FINDERS",
    "FITS",
    "FIT_PARAMS",
    "METHODS",
    "ORIENTATIONS",
    "PRESETS",
    "PREVIEW_FIELDS",
    "PREVIEW_VIEWS",
    "CurvatureInputError",
    "CurvatureResult",
    "FormatError",
    "NonFiniteError",
    "Neighborhoods",
    "ParamSpec",
    "ParameterError",
    "PointCloud",
    "Status",
    "TooFewPointsError",
    "UnknownFormatError",
    "estimate",
    "neighbors",
    "read",
    "render_preview",
    "synthetic",
    "write",
]
