"""Parameter errors in the library's words: the method, the parameter, what it must be.

The request models reject bad parameters before the library sees them; their messages
("Input should be greater than or equal to 5") name neither the method nor the bound's
meaning. Where the parameter is one of the library's :class:`curvature.ParamSpec`, its own
check gives the message (``method 'knn': parameter 'k' must be >= 5, got 0; allowed: 5 to
1024``), so the CLI, the library and the service say the same thing.
"""

from __future__ import annotations

from typing import Any

import curvature


def _specs(method: str) -> dict[str, curvature.ParamSpec]:
    if method == "auto":
        return {s.name: s for s in curvature.AUTO_PARAMS}
    return {s.name: s for s in (*curvature.FINDERS[method].PARAMS, *curvature.FIT_PARAMS)}


def _accepted(method: str) -> list[str]:
    names = set(_specs(method)) | {"orientation", "viewpoint"}
    return sorted(names if method == "auto" else names | {"fit"})


def parameter_message(raw: Any, error: dict) -> str:
    """One pydantic error of the params union as the library would phrase it.

    Parameters
    ----------
    raw : Any
        The ``params`` value the client sent (a dict when it got as far as a method).
    error : dict
        A pydantic error whose ``loc`` starts with the method tag, as a discriminated union
        reports it, e.g. ``("knn", "k")``; ``()`` when the method itself is wrong.
    """
    if not isinstance(raw, dict):
        return f"params must be a JSON object, got {type(raw).__name__}"
    loc = tuple(error.get("loc", ()))
    if not loc or loc[0] not in curvature.METHODS:
        return f"unknown method {raw.get('method')!r}; choose one of {list(curvature.METHODS)}"
    method, rest = loc[0], loc[1:]
    owner = f"method '{method}'"
    if not rest:
        return f"{owner}: {error.get('msg', 'invalid parameters')}"
    name = str(rest[0])
    value = raw.get(name)
    if error.get("type") == "extra_forbidden":
        if method == "auto" and name == "fit":
            return (f"{owner} chooses its own fit; fit {value!r} needs a neighborhood method "
                    f"({', '.join(sorted(curvature.FINDERS))})")
        return f"{owner}: unknown parameter(s) {[name]}; accepted: {_accepted(method)}"
    if name == "fit":
        return f"{owner}: unknown fit {value!r}; choose one of {list(curvature.FITS)}"
    if name == "orientation":
        return (f"{owner}: unknown orientation {value!r}; choose one of "
                f"{list(curvature.ORIENTATIONS)}")
    spec = _specs(method).get(name)
    if spec is not None:
        try:
            spec.check(value, owner)
        except curvature.ParameterError as exc:
            return str(exc)
        except (OverflowError, ValueError, TypeError):  # e.g. int(inf): the generic words
            pass
    msg = error.get("msg") or "invalid value"
    return f"{owner}: parameter '{name}': {msg[:1].lower()}{msg[1:]}"
