"""Columnar JSON: ``{"n": n, "fields": {name: [...]}, "faces": [...], "info": {...}}``.

Scalars are lists of numbers, vectors lists of ``[x, y, z]``; NaN and Inf become ``null``
(JSON has neither). Numbers are the shortest text that reads back to the same value, written
by orjson straight from the arrays, block by block, so a result is never held as Python lists.
"""

from __future__ import annotations

import json
from typing import BinaryIO

import numpy as np

from .columns import Table
from .tokens import json_numbers

_CHUNK_ROWS = 65536


def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


def _clean(value):
    """Info values as strict JSON (NaN -> None)."""
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def write_json(fh: BinaryIO, table: Table) -> None:
    """Write ``table`` as one columnar JSON object (UTF-8)."""
    fh.write(f'{{"n": {table.n}, "fields": {{'.encode())
    for k, (name, arr) in enumerate(table.fields.items()):
        fh.write(((", " if k else "") + json.dumps(name) + ": [").encode())
        for lo in range(0, table.n, _CHUNK_ROWS):
            fh.write((b"," if lo else b"") + json_numbers(np.asarray(arr[lo:lo + _CHUNK_ROWS])))
        fh.write(b"]")
    fh.write(b"}")
    if table.faces is not None:
        fh.write(b', "faces": [')
        for lo in range(0, len(table.faces), _CHUNK_ROWS):
            fh.write((b"," if lo else b"") + json_numbers(table.faces[lo:lo + _CHUNK_ROWS]))
        fh.write(b"]")
    if table.info:
        info = json.loads(json.dumps(table.info, default=_json_default))
        fh.write(b', "info": ' + json.dumps(_clean(info), allow_nan=False).encode())
    fh.write(b"}")
