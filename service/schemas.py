"""Request and response models; the per-method parameter models are built from the core.

Each neighborhood method of ``curvature.FINDERS`` gets a model whose fields, defaults and
bounds come from the method's ``ParamSpec`` tuple at import time, plus the fields every method
shares (fit model, solver, orientation, viewpoint); method "auto" (the default, which picks its
own fit and scale) gets its ``curvature.AUTO_PARAMS`` and the orientation fields. The models
form a union discriminated by ``method``, so a new method in the core appears in the API and
in OpenAPI by itself.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Annotated, Any, Literal, Union

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    create_model,
    field_validator,
    model_validator,
)

import curvature
from curvature import ParamSpec

from .formats import INPUT_EXTENSIONS, RESULT_FORMATS
from .store import STATUSES

DEFAULT_METHOD = curvature.DEFAULT_METHOD
DEFAULT_FIT = curvature.DEFAULT_FIT

FIT_PARAMS: tuple[ParamSpec, ...] = tuple(curvature.FIT_PARAMS)
# Parameters that only make sense for some fit models (name -> those models).
FIT_ONLY: dict[str, tuple[str, ...]] = dict(curvature.fitting.FIT_ONLY)


def _not_bool(value: Any) -> Any:
    """JSON ``true``/``false`` is not a number (pydantic's lax mode would read 1 and 0)."""
    if isinstance(value, bool):
        raise ValueError("expected a number, not true or false")
    return value


Number = Annotated[float, BeforeValidator(_not_bool)]


def _annotation(spec: ParamSpec) -> Any:
    if spec.choices:
        return Literal[tuple(spec.choices)]
    if spec.kind is bool:
        return Annotated[bool, Strict()]  # true or false only, not 1 or "yes"
    if spec.kind in (int, float):  # bounds on the number itself, so '| None' keeps them
        bounds = {}
        if spec.minimum is not None:
            bounds["ge"] = spec.minimum
        if spec.maximum is not None:
            bounds["le"] = spec.maximum
        return Annotated[spec.kind, Field(**bounds), BeforeValidator(_not_bool)]
    return spec.kind


def _field(spec: ParamSpec, default: Any) -> Any:
    return Field(default, description=spec.help or None)


def _viewpoint_rule(schema: dict) -> None:
    """Say in the JSON schema what :meth:`OrientationParams._viewpoint_given` enforces:
    orientation 'viewpoint' comes with a viewpoint (without if/then/not)."""
    others = [o for o in curvature.ORIENTATIONS if o != "viewpoint"]
    schema.setdefault("allOf", []).append({"anyOf": [
        {"properties": {"orientation": {"enum": [*others, None]}}},
        {"required": ["viewpoint"], "properties": {"viewpoint": {"type": "array"}}}]})


class OrientationParams(BaseModel):
    """Fields every method shares: orientation and viewpoint."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_viewpoint_rule)

    orientation: Literal[tuple(curvature.ORIENTATIONS)] | None = Field(
        None, description="How normals are oriented (signs of k1, k2, H). Default: 'normals' "
        "when the input has normals, 'viewpoint' when a viewpoint is given, else 'auto'.")
    viewpoint: tuple[Number, Number, Number] | None = Field(
        None, description="Scanner position [x, y, z]; normals are turned to face it.")

    @field_validator("viewpoint")
    @classmethod
    def _finite_viewpoint(cls, value):
        if value is not None and not all(math.isfinite(v) for v in value):
            raise ValueError("viewpoint coordinates must be finite")
        return value

    @model_validator(mode="after")
    def _viewpoint_given(self):
        if self.orientation == "viewpoint" and self.viewpoint is None:
            raise ValueError("orientation 'viewpoint' needs a 'viewpoint'")
        return self


def _fit_only_schema(schema: dict) -> None:
    """Say in the JSON schema what :meth:`CommonParams._consistent` enforces: a fit-only
    parameter (e.g. ``solver``) is refused unless ``fit`` is one of its models (the default
    fit counts when ``fit`` is absent); and the viewpoint rule of every method."""
    _viewpoint_rule(schema)
    rules = []
    default_fit = schema.get("properties", {}).get("fit", {}).get("default")
    for name, only_fits in FIT_ONLY.items():
        if name not in schema.get("properties", {}):
            continue
        # Said without if/then/not (fuzzers read those poorly): the fit is one of its
        # models, or the parameter is absent or null.
        allowed = [{"required": ["fit"], "properties": {"fit": {"enum": list(only_fits)}}},
                   {"properties": {name: {"type": "null"}}}]
        if default_fit in only_fits:  # an absent fit is its model too
            allowed.append({"properties": {"fit": False}})
        rules.append({"anyOf": allowed})
    if rules:
        schema.setdefault("allOf", []).extend(rules)


class CommonParams(OrientationParams):
    """Fields every neighborhood method shares: fit model, orientation and viewpoint."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_fit_only_schema)

    fit: Literal[tuple(curvature.FITS)] = Field(
        DEFAULT_FIT, description="Quadric model fitted to each neighborhood. 'adaptive' (the "
        "default): the implicit quadric where it fits the points (exact on quadrics), the "
        "height function where noise would make it speckle; preset 'paper' is the implicit "
        "one over 10 Territory Claiming neighbors.")

    @model_validator(mode="after")
    def _consistent(self):
        for name, only_fits in FIT_ONLY.items():
            if getattr(self, name, None) is not None and self.fit not in only_fits:
                raise ValueError(f"'{name}' applies to fit "
                                 f"{' and '.join(repr(f) for f in only_fits)} only")
        return self


def _fit_fields() -> dict[str, Any]:
    # Fit-only parameters default to None ("the library's default") so the consistency
    # check above can tell an explicit value from an absent one.
    fields = {}
    for spec in FIT_PARAMS:
        default = None if spec.name in FIT_ONLY else spec.default
        annotation = _annotation(spec) | None if default is None else _annotation(spec)
        fields[spec.name] = (annotation, _field(spec, default))
    return fields


def _method_model(name: str, finder: type) -> type[BaseModel]:
    fields: dict[str, Any] = {"method": (Literal[name], Field(description="Neighborhood method."))}
    fields.update(_fit_fields())
    for spec in finder.PARAMS:
        fields[spec.name] = (_annotation(spec), _field(spec, spec.default))
    doc = (finder.__doc__ or "").strip().splitlines()
    model = create_model(f"{name.capitalize()}Params", __base__=CommonParams,
                         __doc__=f"Parameters of method '{name}'. {doc[0] if doc else ''}".strip(),
                         **fields)
    return model


AUTO_DESCRIPTION = ("Measures the cloud's noise and spacing and picks model and scale itself: "
                    "the implicit quadric on clean clouds; on noisy ones, fits of the estimated "
                    "normals over large neighborhoods (a quadric whose gradient follows them, or "
                    "a cubic normal field where that fits them clearly better).")


def _auto_model() -> type[BaseModel]:
    # Parameters without 'method' are the default method's: the schema says so by leaving
    # 'method' optional there (and required in every other method's parameters).
    tag = Field("auto", description="Method.") if DEFAULT_METHOD == "auto" else \
        Field(description="Method.")
    fields: dict[str, Any] = {"method": (Literal["auto"], tag)}
    for spec in curvature.AUTO_PARAMS:
        fields[spec.name] = (_annotation(spec), _field(spec, spec.default))
    return create_model("AutoParams", __base__=OrientationParams,
                        __doc__=f"Parameters of method 'auto'. {AUTO_DESCRIPTION}", **fields)


METHOD_MODELS: dict[str, type[BaseModel]] = {
    "auto": _auto_model(),
    **{name: _method_model(name, finder) for name, finder in sorted(curvature.FINDERS.items())}}


def _default_method(value: Any) -> Any:
    """Parameters without ``method`` are those of the default method, as in the library."""
    if isinstance(value, dict) and "method" not in value:
        return {"method": DEFAULT_METHOD, **value}
    return value


if len(METHOD_MODELS) > 1:
    MethodParams = Annotated[Union[tuple(METHOD_MODELS.values())],  # noqa: UP007
                             Field(discriminator="method"), BeforeValidator(_default_method)]
else:  # a one-member union cannot carry a discriminator
    MethodParams = Annotated[next(iter(METHOD_MODELS.values())),
                             BeforeValidator(_default_method)]


def default_params() -> BaseModel:
    """Parameters used when a request gives none."""
    return METHOD_MODELS[DEFAULT_METHOD](method=DEFAULT_METHOD)


# -- requests -------------------------------------------------------------------------------

Vector3 = tuple[float, float, float]


def _normals_rule(schema: dict) -> None:
    """Orientation 'normals' comes with ``normals`` (the server refuses it without)."""
    others = [o for o in curvature.ORIENTATIONS if o != "normals"]
    schema.setdefault("allOf", []).append({"anyOf": [
        {"required": ["normals"], "properties": {"normals": {"type": "array"}}},
        {"properties": {"params": {"anyOf": [
            {"type": "null"}, {"properties": {"orientation": {"enum": [*others, None]}}}]}}}]})


class CloudRequest(BaseModel):
    """A cloud sent as JSON arrays (the alternative to a multipart file upload)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra=_normals_rule)

    points: list[Vector3] = Field(min_length=10, description=(
        "Coordinates, one [x, y, z] per point; at least 10 points."))
    normals: list[Vector3] | None = Field(
        None, min_length=10, description="Optional per-point normals, same length as points.")
    faces: list[tuple[int, int, int]] | None = Field(
        None, description="Optional triangles as vertex indices (kept in PLY results).")
    params: MethodParams | None = Field(  # type: ignore[valid-type]
        None, description="Method and fit parameters; without 'method' (or without params) "
        f"method '{DEFAULT_METHOD}' with its defaults.")


class MultipartCloudRequest(BaseModel):
    """A cloud file upload (multipart/form-data)."""

    model_config = ConfigDict(extra="forbid")  # the server refuses any other part

    file: bytes = Field(json_schema_extra={"format": "binary"}, description=(
        "The cloud file; the extension of its file name gives the format: "
        + ", ".join(INPUT_EXTENSIONS) + "."))
    # A JSON text part (encoding application/json in the route), so the schema is the object.
    params: MethodParams | None = Field(  # type: ignore[valid-type]
        None, description=("JSON object with the method and fit parameters, e.g. "
                           "{\"method\": \"knn\", \"k\": 10}."))


# -- responses ------------------------------------------------------------------------------

JobStatus = Literal[STATUSES]


class Problem(BaseModel):
    """An error, as application/problem+json (RFC 9457)."""

    model_config = ConfigDict(extra="allow")

    type: str = Field(description="Stable problem type, e.g. '/problems/too-few-points'.")
    title: str
    status: int
    detail: str
    instance: str | None = Field(None, description="The request path the problem occurred on.")


class JobError(BaseModel):
    """Why a job failed (the same members as a problem document)."""

    type: str
    title: str
    status: int
    detail: str


class JobInput(BaseModel):
    kind: Literal["file", "arrays"]
    filename: str | None = None
    format: str | None = None
    bytes: int


class JobResult(BaseModel):
    formats: list[str] = Field(description="Formats the result can be downloaded in.")
    status_counts: dict[str, int] = Field(description="Number of points per status name.")
    dropped_points: int = 0
    compute_seconds: float | None = None
    tiles: int | None = Field(None, description="Spatial tiles the cloud was computed in "
                              "(executor 'dask', or clouds above 2M points).")


class Job(BaseModel):
    """A curvature job and its state."""

    id: str
    status: JobStatus
    progress: float = Field(ge=0.0, le=1.0)
    method: str
    params: dict[str, Any]
    input: JobInput
    n_points: int | None
    attempts: int = Field(description="Runs charged to the job: those it started and that "
                          "crashed or finished (a run stopped for another job's sake or by a "
                          "server restart is not charged).")
    restarts: int = Field(0, description="Server restarts that interrupted a run of the job.")
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    expires_at: datetime | None
    error: JobError | None
    result: JobResult | None
    links: dict[str, str]


class JobPage(BaseModel):
    items: list[Job]
    next_cursor: str | None = Field(description="Pass as ?cursor= for the next page.")


class ParameterInfo(BaseModel):
    name: str
    type: str
    default: Any
    minimum: float | None = None
    maximum: float | None = None
    choices: list[Any] | None = None
    help: str = ""
    applies_to_fit: list[str] | None = None


class MethodInfo(BaseModel):
    name: str
    description: str
    parameters: list[ParameterInfo]


class FitInfo(BaseModel):
    name: str
    parameters: list[ParameterInfo]


class MethodsResponse(BaseModel):
    methods: list[MethodInfo]
    fits: list[FitInfo]
    orientations: list[str]
    default_method: str
    input_formats: list[str]
    result_formats: list[str]


def parameter_info(spec: ParamSpec, applies_to_fit=None) -> ParameterInfo:
    return ParameterInfo(name=spec.name, type=spec.kind.__name__, default=spec.default,
                         minimum=spec.minimum, maximum=spec.maximum,
                         choices=list(spec.choices) if spec.choices else None, help=spec.help,
                         applies_to_fit=None if applies_to_fit is None
                         else list(applies_to_fit))


def methods_response() -> MethodsResponse:
    """Everything GET /v1/methods reports, from the core's specs."""
    methods = [MethodInfo(name="auto", description=AUTO_DESCRIPTION,
                          parameters=[parameter_info(s) for s in curvature.AUTO_PARAMS])]
    for name, finder in sorted(curvature.FINDERS.items()):
        doc = (finder.__doc__ or "").strip().splitlines()
        methods.append(MethodInfo(name=name, description=doc[0] if doc else "",
                                  parameters=[parameter_info(s) for s in finder.PARAMS]))
    fits = [FitInfo(name=fit, parameters=[
        parameter_info(s, FIT_ONLY.get(s.name)) for s in FIT_PARAMS
        if fit in FIT_ONLY.get(s.name, (fit,))]) for fit in curvature.FITS]
    return MethodsResponse(methods=methods, fits=fits,
                           orientations=list(curvature.ORIENTATIONS),
                           default_method=DEFAULT_METHOD, input_formats=list(INPUT_EXTENSIONS),
                           result_formats=list(RESULT_FORMATS))


def timestamp(value: float | None) -> datetime | None:
    return None if value is None else datetime.fromtimestamp(value, tz=UTC)
