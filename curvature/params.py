"""Declarative parameter specs shared by methods, the CLI and the service schemas."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .errors import ParameterError


@dataclass(frozen=True)
class ParamSpec:
    """One tunable parameter of a neighborhood method or fit model.

    Attributes
    ----------
    name : str
        Keyword name.
    kind : type
        ``int`` or ``float`` (``bool`` and ``str`` for a few switches).
    default : Any
        Value used when the caller gives none.
    minimum, maximum : float or None
        Inclusive bounds.
    help : str
        One line for the CLI and the OpenAPI document.
    choices : tuple or None
        Allowed values for string parameters.
    """

    name: str
    kind: type
    default: Any
    minimum: float | None = None
    maximum: float | None = None
    help: str = ""
    choices: tuple | None = None

    def check(self, value: Any, owner: str) -> Any:
        """Coerce ``value`` to ``kind`` and check its bounds; raise ParameterError otherwise."""
        where = f"{owner}: parameter '{self.name}'"
        if self.kind is bool:
            if not isinstance(value, bool | int):
                raise ParameterError(f"{where} must be true or false, got {value!r}")
            return bool(value)
        if self.kind is str:
            if self.choices is not None and value not in self.choices:
                raise ParameterError(f"{where} must be one of {list(self.choices)}, got {value!r}")
            return str(value)
        if isinstance(value, bool):
            raise ParameterError(f"{where} must be a number, got {value!r}")
        try:
            coerced = self.kind(value)
        except (TypeError, ValueError):
            raise ParameterError(f"{where} must be {self.kind.__name__}, got {value!r}") from None
        if self.kind is int and float(coerced) != float(value):
            raise ParameterError(f"{where} must be a whole number, got {value!r}")
        if self.kind is float and not (coerced == coerced and abs(coerced) != float("inf")):
            raise ParameterError(f"{where} must be finite, got {value!r}")
        # A value out of a two-sided range is told the whole range, not just the bound it hit.
        allowed = ("" if self.minimum is None or self.maximum is None
                   else f"; allowed: {self.minimum} to {self.maximum}")
        if self.minimum is not None and coerced < self.minimum:
            raise ParameterError(f"{where} must be >= {self.minimum}, got {value!r}{allowed}")
        if self.maximum is not None and coerced > self.maximum:
            raise ParameterError(f"{where} must be <= {self.maximum}, got {value!r}{allowed}")
        return coerced


def resolve_params(specs: tuple[ParamSpec, ...], given: dict[str, Any], owner: str) -> dict:
    """Merge ``given`` over the defaults of ``specs``, checking names, types and bounds.

    Parameters
    ----------
    specs : tuple of ParamSpec
        The parameters the owner accepts.
    given : dict
        Caller's values; ``None`` values mean "use the default".
    owner : str
        Name used in error messages, e.g. ``"method 'tc'"``.

    Returns
    -------
    dict
        Every parameter of ``specs`` with a checked value.
    """
    known = {s.name: s for s in specs}
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise ParameterError(
            f"{owner}: unknown parameter(s) {unknown}; accepted: {sorted(known) or 'none'}")
    out = {}
    for spec in specs:
        value = given.get(spec.name)
        out[spec.name] = spec.default if value is None else spec.check(value, owner)
    return out
