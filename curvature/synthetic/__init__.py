"""Analytic test shapes with exact normals, principal curvatures and principal directions.

Every shape is a parametric surface r(u, v). Points are sampled either uniformly with respect
to surface area (``sampling="area"``) or uniformly in the parameters (``sampling="parameter"``),
and the exact differential geometry is computed at every sample from the analytic derivatives
r_u, r_v, r_uu, r_uv, r_vv by one shared routine (:func:`surface_geometry`), so all shapes use
the same code path. Optional Gaussian noise, with standard deviation given in percent of the
bounding-box diagonal (BBD) of the clean cloud, is added afterwards (DESIGN.md section 8).

Sign convention (DESIGN.md section 3): a curvature is positive where the surface bends away
from the oriented normal, so a sphere with outward normals has k1 = k2 = +1/r; k1 >= k2
(signed order). All normals returned here point outward (closed shapes) or have a positive
z component (height-field-like shapes: plane, saddle, Bezier patch).

Shapes by family: :mod:`~curvature.synthetic.smooth` (sphere, ellipsoid, cylinder, plane,
saddle, torus), :mod:`~curvature.synthetic.bezier` (the bicubic patch) and
:mod:`~curvature.synthetic.parts` (machined parts); :mod:`~curvature.synthetic.base` holds what
they share, :mod:`~curvature.synthetic.shapes` names them all.

Examples
--------
>>> from curvature import synthetic
>>> cloud = synthetic.torus(10_000, noise=0.25, seed=1)
>>> cloud.points.shape, cloud.k1.shape
((10000, 3), (10000,))

Command line::

    curvature synthetic torus --n 10000 --noise 0.25 --noise-model direction \
        --seed 1 -o torus.ply
"""

from .base import NOISE_MODELS, SAMPLINGS, VIEW_DIRECTION, SyntheticCloud, surface_geometry
from .bezier import BEZIER_DEFAULT_HEIGHTS, bezier_control_net, bezier_patch
from .cli import main
from .parts import PART_SHAPES, blade, filleted_box, filleted_cylinder, thin_plate
from .shapes import SHAPES, make
from .smooth import cylinder, ellipsoid, plane, saddle, sphere, torus

__all__ = [
    "BEZIER_DEFAULT_HEIGHTS",
    "NOISE_MODELS",
    "PART_SHAPES",
    "SAMPLINGS",
    "SHAPES",
    "VIEW_DIRECTION",
    "SyntheticCloud",
    "bezier_control_net",
    "bezier_patch",
    "blade",
    "cylinder",
    "ellipsoid",
    "filleted_box",
    "filleted_cylinder",
    "main",
    "make",
    "plane",
    "saddle",
    "sphere",
    "surface_geometry",
    "thin_plate",
    "torus",
]
