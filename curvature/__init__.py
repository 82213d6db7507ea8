"""Per-point curvature of noisy 3D scans by local quadric fitting.

Public surface (DESIGN.md section 5)::

    import curvature
    res = curvature.estimate(points, method="knn", fit="implicit")
    cloud = curvature.read("scan.ply")
    curvature.write("out.ply", res)
"""

from . import synthetic
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
from .pipeline import FITS, ORIENTATIONS, estimate
from .result import CurvatureResult
from .status import Status

__version__ = "0.1.0"

__all__ = [
    "FINDERS",
    "FITS",
    "FIT_PARAMS",
    "ORIENTATIONS",
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
    "synthetic",
    "write",
]
