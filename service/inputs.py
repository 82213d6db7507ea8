"""Loading a job's input and the checks every cloud passes before the library sees it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

import curvature

from .input_guard import check_numpy_file
from .problem_types import ProblemError

# The library refuses smaller clouds (DESIGN.md section 3); checked here first so the
# error gets its own problem type.
MIN_POINTS = 10


@dataclass
class CloudInput:
    """Arrays handed to ``curvature.estimate``."""

    points: np.ndarray
    normals: np.ndarray | None = None
    faces: np.ndarray | None = None
    dropped: int = 0
    # The cloud as read from a file: its attributes, index and viewpoint go to the result.
    cloud: curvature.PointCloud | None = None


def load_input(path: Path, kind: str, display_name: str | None,
               max_points: int | None = None) -> CloudInput:
    """Read a job's input: an uploaded file (any library format) or stored JSON arrays.

    NPY/NPZ files are first checked by their declared shapes and compression against
    ``max_points`` (:mod:`service.input_guard`), so a bomb is refused before it inflates.
    """
    if kind != "arrays":
        check_numpy_file(path, display_name or path.name, max_points)
    if kind == "arrays":
        with np.load(path, allow_pickle=False) as data:
            return CloudInput(points=data["points"],
                              normals=data["normals"] if "normals" in data else None,
                              faces=data["faces"] if "faces" in data else None)
    try:
        cloud = curvature.read(path)
    except curvature.FormatError as exc:
        raise _file_problem(exc, display_name or path.name) from None
    except curvature.CurvatureInputError as exc:
        raise ProblemError("invalid-cloud", f"{display_name or path.name}: {exc}") from None
    return CloudInput(points=cloud.points, normals=cloud.normals, faces=cloud.faces,
                      dropped=int(getattr(cloud, "dropped", 0) or 0), cloud=cloud)


def _file_problem(exc: curvature.FormatError, display_name: str) -> ProblemError:
    """Re-word a library format error with the client's file name, not our storage path."""
    where = [f"line {exc.line}"] if exc.line is not None else []
    if exc.offset is not None:
        where.append(f"byte {exc.offset}")
    name = display_name + (f" ({', '.join(where)})" if where else "")
    return ProblemError(_file_problem_slug(exc), f"{name}: {exc.reason}")


def _file_problem_slug(exc: curvature.FormatError) -> str:
    if isinstance(exc, curvature.UnknownFormatError):
        return "unknown-format"
    if isinstance(exc, curvature.NonFiniteError):
        return "non-finite-coordinates"
    if isinstance(exc, curvature.TooFewPointsError):
        return "too-few-points"
    return "malformed-file"


def check_cloud(cloud: CloudInput) -> None:
    """Reject clouds the library cannot use, each with its own problem type."""
    pts = np.asarray(cloud.points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ProblemError("invalid-cloud", f"points must have shape (n, 3), got {pts.shape}")
    if pts.shape[0] < MIN_POINTS:
        raise ProblemError("too-few-points",
                           f"the cloud has {pts.shape[0]} point(s); at least {MIN_POINTS} "
                           "are needed")
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        raise ProblemError("non-finite-coordinates",
                           f"{bad.size} point(s) have NaN or infinite coordinates, "
                           f"the first at index {bad[0]}")
    if cloud.normals is not None and np.shape(cloud.normals) != pts.shape:
        raise ProblemError("invalid-cloud", f"normals must have shape {pts.shape}, "
                           f"got {np.shape(cloud.normals)}")
