"""Result files of a job: the canonical NPZ written once, and the formats rendered from it.

A finished job stores every result array in one uncompressed NPZ (fast to write and read);
JSON, PLY, CSV and NPZ as served are rendered from it by the library on first request and kept
next to it. Every file is written to a temporary name and renamed into place.
"""

from __future__ import annotations

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


def save_canonical(result, path: Path) -> None:
    """Store every array of a result in one NPZ (temp file, then atomic rename)."""
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
        os.replace(tmp, path)
    except BaseException:
        # A full disk must not leave a partial file behind to fill it further.
        tmp.unlink(missing_ok=True)
        raise


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


def render(job_dir: str, fmt: str) -> str:
    """Path of a finished job's result in ``fmt``, written on first request and kept."""
    folder = Path(job_dir)
    target = folder / f"result.{fmt}"
    if not target.exists():
        write_result(load_canonical(folder / CANONICAL_RESULT), target, fmt)
    return str(target)
