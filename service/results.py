"""Result format negotiation: ``?format=`` first, then the Accept header, else JSON."""

from __future__ import annotations

from .formats import RESULT_FORMATS, RESULT_MEDIA_TYPES
from .problems import HTTPProblem

DEFAULT_FORMAT = "json"

# Media types (and wildcards) a client may put in Accept, and the format each selects.
ACCEPTED_MEDIA_TYPES = {
    "application/json": "json",
    "application/x-ply": "ply",
    "application/ply": "ply",
    "model/ply": "ply",
    "model/x-ply": "ply",
    "application/octet-stream": "ply",
    "text/csv": "csv",
    "application/csv": "csv",
    "application/x-npz": "npz",
    "application/zip": "npz",
    "application/vnd.las": "las",
    "application/vnd.laszip": "laz",
    "application/*": "json",
    "model/*": "ply",
    "text/*": "csv",
    "*/*": DEFAULT_FORMAT,
}


def _parse_accept(header: str) -> list[tuple[float, int, str]]:
    """Accept entries as (q, position, media type), best first; q=0 entries dropped."""
    entries = []
    for position, item in enumerate(header.split(",")):
        parts = [p.strip() for p in item.split(";")]
        media = parts[0].lower()
        if not media:
            continue
        q = 1.0
        for param in parts[1:]:
            key, _, value = param.partition("=")
            if key.strip().lower() == "q":
                try:
                    q = float(value)
                except ValueError:
                    q = 0.0
        if q > 0:
            entries.append((q, position, media))
    # Higher q first; at equal q a concrete type beats a wildcard, then header order.
    entries.sort(key=lambda e: (-e[0], e[2].count("*"), e[1]))
    return entries


def negotiate(format_param: str | None, accept: str | None) -> str:
    """Pick the result format.

    Parameters
    ----------
    format_param : str or None
        Value of ``?format=`` (already checked to be one of RESULT_FORMATS); wins if given.
    accept : str or None
        The Accept header.

    Raises
    ------
    HTTPProblem
        406 when Accept names only media types the service cannot produce.
    """
    if format_param:
        return format_param
    if not accept or not accept.strip():
        return DEFAULT_FORMAT
    for _, _, media in _parse_accept(accept):
        fmt = ACCEPTED_MEDIA_TYPES.get(media)
        if fmt is not None:
            return fmt
    offered = ", ".join(sorted(set(ACCEPTED_MEDIA_TYPES) - {"*/*"}))
    raise HTTPProblem("not-acceptable", f"Accept {accept!r} matches no result format; use "
                      f"?format={'|'.join(RESULT_FORMATS)} or one of: {offered}")


def media_type(fmt: str) -> str:
    return RESULT_MEDIA_TYPES[fmt]


def content_disposition(stem: str, fmt: str) -> str:
    return f'attachment; filename="{stem}.{fmt}"'
