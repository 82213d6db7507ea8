"""LZF decompression (the codec of PCD ``binary_compressed`` bodies).

LZF is a byte stream of runs. A control byte ``c < 32`` starts a literal run of ``c + 1``
bytes copied as they are. Otherwise ``c >> 5`` is the match length minus 2 (7 means a further
length byte follows and is added), ``c & 31`` the high 5 bits of the distance minus 1, and the
next byte its low 8 bits: copy ``length`` bytes from ``distance`` bytes back in the output.
The copy may overlap its own output (a run of one repeated byte), so it is done byte by byte.
The loop is sequential by nature, hence numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Worst case ratio: a 3-byte back reference produces 264 bytes, so anything claiming more
# than ~88x expansion is corrupt; checked before the output buffer is allocated.
MAX_RATIO = 264 / 3

_ERRORS = {
    1: "a literal run goes past the end of the compressed data",
    2: "the data decompresses to more bytes than announced",
    3: "a back reference is cut off at the end of the compressed data",
    4: "a back reference points before the start of the output",
    5: "the data decompresses to fewer bytes than announced",
}


class LZFError(ValueError):
    """Corrupt LZF data; ``position`` is the byte index in the compressed stream."""

    def __init__(self, message: str, position: int):
        super().__init__(message)
        self.position = position


def lzf_decompress(data, size: int) -> np.ndarray:
    """Decompress an LZF block.

    Parameters
    ----------
    data : bytes-like or ndarray of uint8
        The compressed block.
    size : int
        The announced uncompressed size.

    Returns
    -------
    ndarray, shape (size,), uint8

    Raises
    ------
    LZFError
        Corrupt data or a size that disagrees with the stream.
    """
    src = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    if size > MAX_RATIO * src.size + 1:
        raise LZFError(f"{src.size} compressed bytes cannot expand to {size} bytes", 0)
    out = np.empty(size, dtype=np.uint8)
    produced, error, position = _decode(src, out)
    if error:
        raise LZFError(_ERRORS[error] + f" (after {produced} of {size} bytes)", int(position))
    return out


@njit(cache=True)
def _decode(src, out):
    """Returns ``(bytes written, error code, input position of the failing run)``."""
    n = src.size
    m = out.size
    i = 0
    o = 0
    while i < n:
        start = i
        ctrl = np.int64(src[i])
        i += 1
        if ctrl < 32:
            length = ctrl + 1
            if i + length > n:
                return o, 1, start
            if o + length > m:
                return o, 2, start
            out[o:o + length] = src[i:i + length]
            i += length
            o += length
        else:
            length = ctrl >> 5
            if length == 7:
                if i >= n:
                    return o, 3, start
                length += np.int64(src[i])
                i += 1
            if i >= n:
                return o, 3, start
            ref = o - ((ctrl & 31) << 8) - 1 - np.int64(src[i])
            i += 1
            length += 2
            if ref < 0:
                return o, 4, start
            if o + length > m:
                return o, 2, start
            for k in range(length):
                out[o + k] = out[ref + k]
            o += length
    if o != m:
        return o, 5, n
    return o, 0, n
