"""Per-point curvature of noisy 3D scans by local quadric fitting.

Public surface (DESIGN.md section 5)::

    import curvature
    res = curvature.estimate(points)                  # method "auto": model and scale measured
    res = curvature.estimate(points, preset="paper")  # the paper's TC + implicit quadric
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
from .estimators.auto import AUTO_PARAMS
from .field_info import FieldInfo
from .field_info import describe as describe_field
from .fitting import FIT_PARAMS
from .io import read, write
from .neighborhoods import FINDERS, Neighborhoods, neighbors
from .params import ParamSpec
from .pipeline import DEFAULT_FIT, DEFAULT_METHOD, FITS, METHODS, ORIENTATIONS, PRESETS, estimate
from .preview import FIELDS as PREVIEW_FIELDS
from .preview import UP_CHOICES as PREVIEW_UP_CHOICES
from .preview import VIEWS as PREVIEW_VIEWS
from .preview import auto_up, render_preview
from .result import CurvatureResult, curvedness, shape_index
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
    "PREVIEW_UP_CHOICES",
    "PREVIEW_VIEWS",
    "CurvatureInputError",
    "CurvatureResult",
    "FieldInfo",
    "FormatError",
    "NonFiniteError",
    "Neighborhoods",
    "ParamSpec",
    "ParameterError",
    "PointCloud",
    "Status",
    "TooFewPointsError",
    "UnknownFormatError",
    "auto_up",
    "curvedness",
    "describe_field",
    "estimate",
    "neighbors",
    "read",
    "render_preview",
    "shape_index",
    "synthetic",
    "write",
]
