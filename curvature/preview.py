"""Preview pictures: a cloud seen from a fixed camera, colored by a curvature field.

The cloud is projected orthographically and rasterized here with a z-buffer (each pixel shows
the nearest point; points are drawn as small disks sized to close the gaps between them), then
matplotlib (Agg, imported lazily: an optional dependency) adds the title and a color bar. Doing
the projection ourselves keeps the time bounded and independent of matplotlib's 3D machinery:
clouds larger than ``max_points`` are subsampled deterministically first.
"""

from __future__ import annotations

import importlib.util
import io
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .errors import CurvatureInputError, ParameterError
from .field_info import describe
from .io.atomic import atomic_open
from .validation import as_points

FIELDS: dict[str, str] = {
    "mean": "mean curvature H",
    "gaussian": "Gaussian curvature K",
    "k1": "principal curvature k1",
    "k2": "principal curvature k2",
    "k1_std": "standard error of k1",
    "k2_std": "standard error of k2",
    "mean_std": "standard error of H",
}
# Camera presets in the world frame (right, forward, up) of the chosen up axis: (direction
# from the cloud towards the camera, screen up). With z up: right = x and forward = y.
VIEWS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "iso": ((1.0, -1.0, 1.0), (0.0, 0.0, 1.0)),
    "front": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "side": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
}
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
UP_CHOICES = ("auto", "x", "-x", "y", "-y", "z", "-z")
# Auto up (see auto_up): a cloud is flat when its smallest principal variance is below this
# share of the largest; an object stands on a ground through the origin when its centroid is
# off the origin by more than this many standard deviations along one axis.
FLAT_RATIO = 0.05
OFFSET_SPREADS = 1.0
AUTO_SAMPLE = 100_000

MAX_POINTS = 400_000
PERCENTILES = (2.0, 98.0)
NAN_COLOR = (0.62, 0.62, 0.62, 1.0)
BACKGROUND = (1.0, 1.0, 1.0, 1.0)
DIVERGING_MAP = "RdBu_r"
SEQUENTIAL_MAP = "viridis"
MAX_DISK_RADIUS = 8

# Figure layout as fractions of the picture: the cloud on the left, the color bar on the right.
PLOT_BOX = (0.01, 0.06, 0.80, 0.85)
COLORBAR_BOX = (0.84, 0.12, 0.035, 0.72)


def auto_up(points: np.ndarray) -> np.ndarray:
    """The up direction of a cloud, chosen from its principal axes.

    1. Flat clouds (smallest principal variance below :data:`FLAT_RATIO` of the largest: a
       table-top scene, a floor, terrain) have up along their smallest principal axis, the
       plane's normal, pointing to the side of the plane where the origin lies: in a scanner's
       frame (PCL, OpenNI) the origin is the sensor, which sees the top of a table.
    2. Other clouds (objects) stand on a ground through the origin when their centroid is
       off the origin along one coordinate axis by more than :data:`OFFSET_SPREADS` standard
       deviations of the cloud along that axis (the Stanford bunny, y up, sits at y > 0): up
       is that axis, signed by the offset.
    3. Otherwise z (the CAD and survey convention).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Finite coordinates; at most :data:`AUTO_SAMPLE` of them (a fixed subsample) are used.

    Returns
    -------
    ndarray, shape (3,)
        Unit vector.
    """
    pts = np.asarray(points, dtype=np.float64)
    keep = subsample(len(pts), AUTO_SAMPLE)
    if keep is not None:
        pts = pts[keep]
    centroid = pts.mean(axis=0)
    centred = pts - centroid
    variances, axes = np.linalg.eigh(centred.T @ centred / max(len(pts), 1))
    if variances[-1] > 0.0 and variances[0] < FLAT_RATIO * variances[-1]:
        normal = axes[:, 0]
        side = float(-centroid @ normal)  # where the origin lies, seen from the plane
        return normal if side >= 0.0 else -normal
    spread = np.sqrt(np.maximum(variances @ (axes * axes).T, 0.0))  # per-axis std
    with np.errstate(divide="ignore", invalid="ignore"):
        offsets = np.where(spread > 0.0, np.abs(centroid) / spread, 0.0)
    best = int(np.argmax(offsets))
    if offsets[best] > OFFSET_SPREADS:
        up = np.zeros(3)
        up[best] = np.sign(centroid[best])
        return up
    return np.array(AXES["z"])


def up_vector(up, points: np.ndarray | None = None) -> np.ndarray:
    """The up direction asked for: an axis name, ``"auto"`` or a vector.

    Parameters
    ----------
    up : {"auto", "x", "-x", "y", "-y", "z", "-z"} or array_like, shape (3,)
    points : ndarray, shape (n, 3), optional
        Needed for ``"auto"`` (see :func:`auto_up`).

    Returns
    -------
    ndarray, shape (3,)
        Unit vector.
    """
    if isinstance(up, str):
        if up not in UP_CHOICES:
            raise ParameterError(f"up must be one of {list(UP_CHOICES)} or a 3-vector, "
                                 f"got {up!r}")
        if up == "auto":
            if points is None:
                raise ParameterError("up='auto' needs the points")
            return auto_up(points)
        vector = np.array(AXES[up[-1]])
        return -vector if up.startswith("-") else vector
    vector = np.asarray(up, dtype=np.float64)
    length = float(np.linalg.norm(vector)) if vector.shape == (3,) else 0.0
    if not np.isfinite(length) or length == 0.0:
        raise ParameterError(f"up must be a non-zero finite 3-vector, got {up!r}")
    return vector / length


def world_frame(up) -> np.ndarray:
    """A right-handed frame around an up direction.

    Right is the x axis made perpendicular to ``up`` (the y axis when up is close to x), and
    forward = up x right: with z up this is (x, y, z), with y up (x, -z, y), with -y up, a
    scanner's camera frame, (x, z, -y), so that ``front`` looks the way the scanner did.

    Parameters
    ----------
    up : array_like, shape (3,)
        Unit vector.

    Returns
    -------
    ndarray, shape (3, 3)
        Rows: right, forward, up.
    """
    u = np.asarray(up, dtype=np.float64)
    seed = np.array(AXES["x"]) if abs(u[0]) < 0.9 else np.array(AXES["y"])
    right = seed - (seed @ u) * u
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(u, right), u])


def camera(view: str, up=AXES["z"]) -> np.ndarray:
    """Rotation of a camera preset.

    Parameters
    ----------
    view : {"iso", "front", "side", "top"}
    up : array_like, shape (3,)
        World up (unit vector); the presets are defined in :func:`world_frame` of it.

    Returns
    -------
    ndarray, shape (3, 3)
        Rows: screen right, screen up, towards the camera (unit, orthonormal).
    """
    if view not in VIEWS:
        raise ParameterError(f"view must be one of {sorted(VIEWS)}, got {view!r}")
    frame = world_frame(up)
    eye, screen_up = (np.asarray(v, dtype=np.float64) @ frame for v in VIEWS[view])
    eye /= np.linalg.norm(eye)
    right = np.cross(screen_up, eye)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(eye, right), eye])


def up_label(up, vector: np.ndarray) -> str:
    """How the title names the up direction: ``"-y"``, or ``"auto (0.01, -0.96, -0.28)"``."""
    for name, axis in AXES.items():
        for sign, prefix in ((1.0, ""), (-1.0, "-")):
            if np.allclose(vector, sign * np.asarray(axis), atol=1e-9):
                return f"{prefix}{name}" + (" (auto)" if up == "auto" else "")
    text = "(" + ", ".join(f"{c:.2f}" for c in vector) + ")"
    return f"auto {text}" if up == "auto" else text


def color_limits(values: np.ndarray, field: str) -> tuple[float, float, bool]:
    """Robust color limits of a field: the 2nd to 98th percentile of its finite values.

    Mean and Gaussian curvature, and principal curvatures of both signs, get limits symmetric
    around 0 (so white means flat) and a diverging map; a principal curvature of one sign
    gets a sequential map over its own range.

    Parameters
    ----------
    values : ndarray, shape (n,)
        May hold NaN (ignored).
    field : str
        One of :data:`FIELDS`.

    Returns
    -------
    vmin, vmax : float
        ``vmin < vmax`` always (a constant field gets a small range around its value).
    diverging : bool
        Whether the limits are symmetric around 0.
    """
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return -1.0, 1.0, True
    lo, hi = (float(v) for v in np.percentile(finite, PERCENTILES))
    diverging = field in ("mean", "gaussian") or lo < 0.0 < hi
    if diverging:
        half = max(abs(lo), abs(hi))
        half = half if half > 0.0 else 1.0
        return -half, half, True
    if hi - lo <= 1e-12 * max(abs(lo), abs(hi), 1e-300):
        pad = 0.05 * abs(lo) if lo != 0.0 else 1.0
        return lo - pad, hi + pad, False
    return lo, hi, False


def tick_exponent(magnitude: float) -> int:
    """Power of ten (a multiple of 3) that brings color-bar ticks of this size to 0.01-9999.

    Parameters
    ----------
    magnitude : float
        Largest absolute value on the bar.

    Returns
    -------
    int
        0 when the ticks read well as they are.
    """
    if not np.isfinite(magnitude) or magnitude <= 0.0 or 1e-2 <= magnitude < 1e4:
        return 0
    return int(3 * np.floor(np.log10(magnitude) / 3.0))


def bar_label(field: str, exponent: int = 0) -> str:
    """Color-bar label: the field's name and unit, with the ticks' power of ten, e.g.
    ``"Gaussian curvature K [10^3 1/length unit²]"``."""
    info = describe(field)
    if exponent == 0:
        return info.axis_label()
    return f"{info.label} [10^{exponent} {info.unit}]" if info.unit else \
        f"{info.label} [10^{exponent}]"


def subsample(n: int, max_points: int, seed: int = 0) -> np.ndarray | None:
    """Sorted indices of ``max_points`` of ``n`` points drawn with a fixed seed, or ``None``
    when every point is kept."""
    if max_points < 1:
        raise ParameterError(f"max_points must be >= 1, got {max_points}")
    if n <= max_points:
        return None
    return np.sort(np.random.default_rng(seed).choice(n, size=max_points, replace=False))


def _disk(radius: int) -> tuple[np.ndarray, np.ndarray]:
    d = np.arange(-radius, radius + 1)
    dx, dy = (a.ravel() for a in np.meshgrid(d, d))
    inside = dx * dx + dy * dy <= radius * radius + radius  # rounder than r^2 for small r
    return dx[inside], dy[inside]


def rasterize(screen: np.ndarray, rgba: np.ndarray, width: int, height: int,
              margin: int = 4) -> np.ndarray:
    """Z-buffer image of projected points.

    Parameters
    ----------
    screen : ndarray, shape (n, 3)
        Screen right, screen up and depth (larger = nearer the camera) of each point.
    rgba : ndarray, shape (n, 4)
        Color of each point, floats in [0, 1].
    width, height : int
        Image size in pixels.
    margin : int
        Empty pixels kept around the cloud.

    Returns
    -------
    ndarray, shape (height, width, 4), float64
        Background where no point projects, else the color of the nearest point.
    """
    image = np.empty((height, width, 4))
    image[:] = BACKGROUND
    n = screen.shape[0]
    if n == 0:
        return image
    lo, hi = screen[:, :2].min(axis=0), screen[:, :2].max(axis=0)
    span = np.where(hi - lo > 0.0, hi - lo, 1.0)
    scale = min((width - 2 * margin - 1) / span[0], (height - 2 * margin - 1) / span[1])
    centre = (lo + hi) / 2.0
    px = np.rint((screen[:, 0] - centre[0]) * scale + (width - 1) / 2.0).astype(np.int64)
    py = np.rint((height - 1) / 2.0 - (screen[:, 1] - centre[1]) * scale).astype(np.int64)

    # Disk size from the mean spacing on screen: the silhouette's area (cells of 8 px hit by
    # a point) shared by the half of the points a closed surface shows to the camera.
    cell = 8
    cells = np.unique((py // cell) * (width // cell + 1) + px // cell).size
    spacing = np.sqrt(cells * cell * cell / max(n / 2.0, 1.0))
    radius = int(np.clip(np.ceil((2.0 * spacing - 1.0) / 2.0), 0, MAX_DISK_RADIUS))
    dx, dy = _disk(radius)

    # Nearest first, then every disk pixel of a point: the first hit of a pixel wins.
    order = np.argsort(-screen[:, 2], kind="stable")
    x = (px[order][:, None] + dx[None, :]).ravel()
    y = (py[order][:, None] + dy[None, :]).ravel()
    owner = np.repeat(order, dx.size)
    inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    pixel = y[inside] * width + x[inside]
    pixels, first = np.unique(pixel, return_index=True)
    image.reshape(-1, 4)[pixels] = rgba[owner[inside][first]]
    return image


def _field_values(result, field: str) -> tuple[np.ndarray, np.ndarray]:
    if field not in FIELDS:
        raise ParameterError(f"field must be one of {list(FIELDS)}, got {field!r}")
    if isinstance(result, Mapping):
        missing = [k for k in ("points", field) if k not in result]
        if missing:
            raise CurvatureInputError(f"the result has no {' or '.join(missing)} array")
        points, values = result["points"], result[field]
    else:
        points, values = result.points, getattr(result, field)
    pts = as_points(points, min_points=1)
    vals = np.asarray(values, dtype=np.float64)
    if vals.shape != (pts.shape[0],):
        raise CurvatureInputError(f"{field}: expected shape ({pts.shape[0]},), got {vals.shape}")
    return pts, vals


MISSING_MATPLOTLIB = "previews need matplotlib: pip install 'curvature[preview]'"


def check_available() -> None:
    """Raise ImportError (saying what to install) when matplotlib is missing."""
    if importlib.util.find_spec("matplotlib") is None:
        raise ImportError(MISSING_MATPLOTLIB)


def _import_matplotlib():
    # Lazily: matplotlib is an optional dependency, and slow to import. Only the object API
    # and the Agg canvas are used (no pyplot state), so renders may run in threads.
    try:
        from matplotlib import colormaps
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize
        from matplotlib.figure import Figure
        from matplotlib.ticker import FuncFormatter
    except ImportError as exc:
        raise ImportError(MISSING_MATPLOTLIB) from exc
    return colormaps, FigureCanvasAgg, ScalarMappable, Normalize, Figure, FuncFormatter


def render_preview(result, field: str = "mean", *, view: str = "iso", up="auto", path=None,
                   width: int = 800, height: int = 600, max_points: int = MAX_POINTS,
                   seed: int = 0, title: str | None = None) -> bytes | Path:
    """Render a PNG of a cloud colored by a curvature field, with a color bar.

    Colors span the 2nd to 98th percentile of the field (symmetric around 0 with a diverging
    map for mean and Gaussian curvature, see :func:`color_limits`); values beyond are drawn in
    the end colors and the color bar shows arrows. Points without a value (NaN, i.e. status
    != 0) are grey.

    Parameters
    ----------
    result : CurvatureResult or Mapping
        Anything with ``points`` (n, 3) and the field (n,) as attributes or keys (e.g. the
        arrays of an NPZ result).
    field : {"mean", "gaussian", "k1", "k2"}
        The field that gives the colors.
    view : {"iso", "front", "side", "top"}
        Camera preset relative to ``up`` (``top`` looks down it), orthographic projection.
    up : {"auto", "x", "-x", "y", "-y", "z", "-z"} or array_like, shape (3,)
        The world's up direction; ``"auto"`` chooses it from the cloud's principal axes
        (:func:`auto_up`): y for the Stanford bunny, about -y for a PCL scanner scene, z for
        a cloud centred on the origin.
    path : str or os.PathLike, optional
        Write the PNG there (atomically) instead of returning its bytes.
    width, height : int
        Picture size in pixels (at least 200 x 150).
    max_points : int
        Larger clouds are drawn from a subsample of this size (drawn with ``seed``), so the
        time stays bounded; color limits still use every point.
    seed : int
        Seed of the subsample.
    title : str, optional
        Defaults to the field's name, the view and the up direction.

    Returns
    -------
    bytes or Path
        The PNG bytes, or ``path`` when given.

    Raises
    ------
    ParameterError
        Unknown field, view or up, or a picture size or ``max_points`` out of range.
    CurvatureInputError
        Missing arrays, wrong shapes or non-finite coordinates.
    ImportError
        matplotlib is not installed (the ``preview`` extra).
    """
    if width < 200 or height < 150:
        raise ParameterError(f"the picture must be at least 200 x 150 pixels, got "
                             f"{width} x {height}")
    points, values = _field_values(result, field)
    up_dir = up_vector(up, points)
    rotation = camera(view, up_dir)
    (colormaps, FigureCanvasAgg, ScalarMappable, Normalize, Figure,
     FuncFormatter) = _import_matplotlib()

    vmin, vmax, diverging = color_limits(values, field)
    norm = Normalize(vmin=vmin, vmax=vmax)
    cmap = colormaps[DIVERGING_MAP if diverging else SEQUENTIAL_MAP].with_extremes(
        bad=NAN_COLOR)
    keep = subsample(len(points), max_points, seed)
    shown_points = points if keep is None else points[keep]
    shown_values = values if keep is None else values[keep]
    rgba = cmap(norm(shown_values))
    rgba[~np.isfinite(shown_values)] = NAN_COLOR

    plot_w = int(round(PLOT_BOX[2] * width))
    plot_h = int(round(PLOT_BOX[3] * height))
    image = rasterize(shown_points @ rotation.T, rgba, plot_w, plot_h)

    fig = Figure(figsize=(width / 100.0, height / 100.0), dpi=100, facecolor=BACKGROUND)
    FigureCanvasAgg(fig)
    ax = fig.add_axes(PLOT_BOX)
    ax.imshow(image, interpolation="nearest", aspect="auto")
    ax.set_axis_off()
    finite = values[np.isfinite(values)]
    below, above = bool(np.any(finite < vmin)), bool(np.any(finite > vmax))
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max",
              (True, True): "both"}[below, above]
    bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=fig.add_axes(COLORBAR_BOX),
                       extend=extend)
    # The power of ten goes into the label, beside the unit: matplotlib would otherwise print
    # an offset or a x10^k multiplier above the bar, apart from the unit it changes.
    exponent = tick_exponent(max(abs(vmin), abs(vmax)))
    bar.formatter = FuncFormatter(lambda v, _pos: f"{v / 10.0 ** exponent:g}")
    bar.update_ticks()
    bar.set_label(bar_label(field, exponent))
    fig.suptitle(title if title is not None else
                 f"{FIELDS[field]} ({view} view, up {up_label(up, up_dir)})", fontsize=12)
    nan_count = int(values.size - finite.size)
    note = f"{len(points):,} points"
    if keep is not None:
        note += f" ({len(keep):,} drawn)"
    note += f", {nan_count:,} without a value (grey)" if nan_count else ""
    note += f"; colors span p{PERCENTILES[0]:g}-p{PERCENTILES[1]:g}"
    fig.text(0.01, 0.015, note, fontsize=8, color="0.3")

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100, facecolor=BACKGROUND)
    data = buffer.getvalue()
    if path is None:
        return data
    with atomic_open(os.fspath(path)) as fh:
        fh.write(data)
    return Path(path)
