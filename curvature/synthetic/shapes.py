"""Every synthetic shape by name: :data:`SHAPES` and :func:`make`."""

from __future__ import annotations

from collections.abc import Callable

from ..errors import ParameterError
from .base import SyntheticCloud
from .bezier import bezier_patch
from .parts import PART_SHAPES
from .smooth import cylinder, ellipsoid, plane, saddle, sphere, torus

#: Shape name -> sampling function.
SHAPES: dict[str, Callable[..., SyntheticCloud]] = {
    "sphere": sphere,
    "ellipsoid": ellipsoid,
    "cylinder": cylinder,
    "plane": plane,
    "saddle": saddle,
    "torus": torus,
    "bezier": bezier_patch,
}
SHAPES.update(PART_SHAPES)


def make(name, n=10000, **kwargs):
    """Sample the shape called ``name`` (a key of :data:`SHAPES`).

    Parameters
    ----------
    name : str
        Shape name; ``"bezier_patch"`` is accepted as an alias of ``"bezier"``.
    n : int
        Number of points.
    **kwargs
        Passed to the shape function (e.g. ``noise=0.25, seed=3, major=3.0``).

    Returns
    -------
    SyntheticCloud
    """
    key = "bezier" if name == "bezier_patch" else name
    try:
        fn = SHAPES[key]
    except KeyError:
        raise ParameterError(
            f"unknown shape {name!r}; known shapes: {', '.join(sorted(SHAPES))}"
        ) from None
    return fn(n, **kwargs)
