"""What each per-point result field means: a label, its unit and how to color it.

Pictures (color bars), the service's field listing and the web viewer all take labels and
units from here, so a field added to the result (e.g. a standard error ``k1_std``) is labelled
by the same rules everywhere. Units follow DESIGN.md section 3: curvature in 1/(input length
unit), Gaussian curvature (k1 * k2) in 1/(length unit)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

from .status import STATUS_NAMES

LENGTH = "length unit"
INVERSE_LENGTH = "1/length unit"
INVERSE_AREA = "1/length unit²"

# How a field is colored: "diverging" (centred on 0), "sequential", "categorical" (integer
# codes with names) or "auto" (diverging when the values have both signs).
SCALES = ("diverging", "sequential", "categorical", "auto")
STD_SUFFIX = "_std"


@dataclass(frozen=True)
class FieldInfo:
    """Description of one per-point field.

    Attributes
    ----------
    label : str
        Human-readable name, e.g. ``"mean curvature H"``.
    unit : str
        Unit of the values (``""`` when dimensionless or a code).
    scale : str
        One of :data:`SCALES`.
    limits : tuple of float, or None
        Fixed color limits when the field has a known range (shape index: -1 to 1).
    categories : dict of int to str, or None
        Names of the codes of a categorical field.
    """

    label: str
    unit: str
    scale: str
    limits: tuple[float, float] | None = None
    categories: dict[int, str] | None = None

    def axis_label(self) -> str:
        """``label [unit]``, or the label alone for a dimensionless field."""
        return f"{self.label} [{self.unit}]" if self.unit else self.label


KNOWN: dict[str, FieldInfo] = {
    "k1": FieldInfo("principal curvature k1", INVERSE_LENGTH, "diverging"),
    "k2": FieldInfo("principal curvature k2", INVERSE_LENGTH, "diverging"),
    "mean": FieldInfo("mean curvature H", INVERSE_LENGTH, "diverging"),
    "gaussian": FieldInfo("Gaussian curvature K", INVERSE_AREA, "diverging"),
    "shape_index": FieldInfo("shape index", "", "diverging", limits=(-1.0, 1.0)),
    "curvedness": FieldInfo("curvedness", INVERSE_LENGTH, "sequential"),
    "residual": FieldInfo("fit residual (RMS distance)", LENGTH, "sequential"),
    "neighbor_count": FieldInfo("neighbors used", "", "sequential"),
    "status": FieldInfo("status", "", "categorical", categories=dict(STATUS_NAMES)),
    "index": FieldInfo("index in the input", "", "sequential"),
    "points": FieldInfo("position", LENGTH, "sequential"),
    "normals": FieldInfo("unit normal", "", "diverging"),
    "dir1": FieldInfo("direction of k1", "", "diverging"),
    "dir2": FieldInfo("direction of k2", "", "diverging"),
}


def describe(name: str) -> FieldInfo:
    """The description of a result field by its name.

    Known fields come from :data:`KNOWN`; ``<field>_std`` is the standard error of a known
    field, in its unit, colored from 0; anything else (an input attribute such as
    ``intensity``) is labelled by its name, without a unit, colored by its values.

    Parameters
    ----------
    name : str

    Returns
    -------
    FieldInfo
    """
    if name in KNOWN:
        return KNOWN[name]
    if name.endswith(STD_SUFFIX) and name[: -len(STD_SUFFIX)] in KNOWN:
        base = KNOWN[name[: -len(STD_SUFFIX)]]
        return FieldInfo(f"standard error of {base.label}", base.unit, "sequential")
    return FieldInfo(name, "", "auto")
