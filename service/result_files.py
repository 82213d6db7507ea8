"""Result files of a job: the canonical NPZ written once, and the formats rendered from it.

A finished job stores every result array in one uncompressed NPZ (fast to write and read);
JSON, PLY, CSV and NPZ as served are rendered from it by the library on first request and kept
next to it. Every file is written to a temporary name and renamed into place.
"""

from __future__ import annotations

import hashlib
import json
import os
import uuid
from pathlib import Path

import numpy as np

import curvature

CANONICAL_RESULT = "result.npz"
# Input attributes (colours, index ...) are stored as "attribute.<name>" arrays.
ATTRIBUTE_PREFIX = "attribute."


def _jsonable(value):
    """``json.dumps`` fallback for numpy scalars and arrays in ``result.info``."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


class ResultCorrupt(Exception):
    """The canonical result file is missing or does not match its recorded digest."""


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def matches(path: Path, expected: str | None) -> bool:
    """True when ``path`` exists and has digest ``expected`` (any digest when ``None``)."""
    try:
        return expected is None or file_sha256(path) == expected
    except FileNotFoundError:
        return False


def save_canonical(result, path: Path) -> str:
    """Store every array of a result in one NPZ (temp file, then atomic rename); return
    the file's SHA-256, recorded in the store and checked whenever the file is used."""
    arrays = dict(result.fields())
    arrays["points"] = result.points
    if result.faces is not None:
        arrays["faces"] = result.faces
    arrays["info"] = np.array(json.dumps(result.info or {}, default=_jsonable))
    arrays.update({ATTRIBUTE_PREFIX + k: v for k, v in result.attributes.items()})
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
        digest = file_sha256(tmp)
        os.replace(tmp, path)
    except BaseException:
        # A full disk must not leave a partial file behind to fill it further.
        tmp.unlink(missing_ok=True)
        raise
    return digest


def load_canonical(path: Path):
    """Rebuild the :class:`curvature.CurvatureResult` saved by :func:`save_canonical`."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {key: data[key] for key in data.files}
    info = json.loads(str(arrays.pop("info")))
    faces = arrays.pop("faces", None)
    attributes = {k[len(ATTRIBUTE_PREFIX):]: arrays.pop(k) for k in list(arrays)
                  if k.startswith(ATTRIBUTE_PREFIX)}
    return curvature.CurvatureResult(faces=faces, info=info, attributes=attributes, **arrays)


def write_result(result, path: Path, fmt: str) -> None:
    """Write ``result`` in ``fmt``; the library writes a temp file and renames it into place."""
    curvature.write(path, result, format=fmt)


def render(job_dir: str, fmt: str, canonical_sha256: str | None = None,
           expected: str | None = None) -> tuple[str, str]:
    """Path and digest of a finished job's result in ``fmt``, written on first request.

    A file already there is used when it matches ``expected`` (its recorded digest);
    otherwise it is written again from the canonical file, which must match
    ``canonical_sha256`` (``None``: not recorded, not checked).

    Raises
    ------
    ResultCorrupt
        The canonical file is missing or fails its checksum.
    """
    folder = Path(job_dir)
    canonical = folder / CANONICAL_RESULT
    target = folder / f"result.{fmt}"
    if target == canonical or (expected is not None and matches(target, expected)):
        if not matches(target, canonical_sha256 if target == canonical else expected):
            raise ResultCorrupt(f"{target.name} is missing or fails its checksum")
        return str(target), canonical_sha256 or file_sha256(target)
    if not matches(canonical, canonical_sha256):
        raise ResultCorrupt(f"{CANONICAL_RESULT} is missing or fails its checksum")
    try:
        result = load_canonical(canonical)
    except (OSError, ValueError, KeyError) as exc:  # unreadable despite an unknown digest
        if isinstance(exc, OSError) and not isinstance(exc, FileNotFoundError):
            raise
        raise ResultCorrupt(f"{CANONICAL_RESULT} cannot be read: {exc}") from None
    write_result(result, target, fmt)
    return str(target), file_sha256(target)
