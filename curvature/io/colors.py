"""Packed colours (PCL's ``rgb``/``rgba``: one 32-bit word per point) as 8-bit channels.

Viewers recognise colours only as separate ``red green blue (alpha)`` unsigned bytes, so
writers expand packed words; the bytes are exactly those of the word (a << 24 | r << 16 |
g << 8 | b), nothing is rescaled.
"""

from __future__ import annotations

import numpy as np

CHANNELS = ("red", "green", "blue")


def unpack_rgb(word: np.ndarray, alpha: bool) -> dict[str, np.ndarray]:
    """Channels of packed colour words.

    Parameters
    ----------
    word : ndarray, shape (n,), uint32 (or float32 holding the bits, as PCL stores them)
    alpha : bool
        Also return ``alpha`` (the top byte).

    Returns
    -------
    dict of str to ndarray, shape (n,), uint8
    """
    w = np.asarray(word)
    if w.dtype == np.float32:
        w = w.view(np.uint32)
    w = w.astype(np.uint32, copy=False)
    out = {name: ((w >> shift) & 0xFF).astype(np.uint8)
           for name, shift in zip(CHANNELS, (16, 8, 0), strict=True)}
    if alpha:
        out["alpha"] = ((w >> 24) & 0xFF).astype(np.uint8)
    return out


def expand_colors(fields: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``fields`` with a packed ``rgb``/``rgba`` column replaced, in place of it, by its channels.

    Left as they are when the file already has a field named like a channel, or the column is
    not a 32-bit word.
    """
    packed = [k for k in ("rgb", "rgba") if k in fields
              and np.asarray(fields[k]).dtype in (np.uint32, np.int32, np.float32)
              and np.asarray(fields[k]).ndim == 1]
    if not packed or any(c in fields for c in (*CHANNELS, "alpha")):
        return fields
    out = {}
    for name, values in fields.items():
        if name == packed[0]:
            out.update(unpack_rgb(values, alpha=name == "rgba"))
        elif name not in packed:
            out[name] = values
    return out
