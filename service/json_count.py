"""Counting the points of a JSON cloud body before it is parsed.

``json.loads`` of a 60 MB body of ``[0,0,0],`` triples builds 7.5 million Python lists, about
1.1 GB, before anyone can tell the cloud has too many points. This scan reads the raw bytes
in small chunks with numpy and counts, for each top-level member (``points``, ``normals``,
``faces``), the arrays nested inside its array: one per point. Its memory is a few bytes per
chunk byte, whatever the body's size, so a cloud above the point limit is refused at once.

Strings are skipped (a quote preceded by a backslash counts as escaped); a body that is not
valid JSON gets counts that mean nothing, and the parser that runs next reports it.
"""

from __future__ import annotations

import numpy as np

CHUNK_BYTES = 1 << 18
_QUOTE, _BACKSLASH = ord('"'), ord("\\")
_OPEN_LIST, _CLOSE_LIST, _OPEN_OBJ, _CLOSE_OBJ = ord("["), ord("]"), ord("{"), ord("}")
# 'r' occurs in true and 's' in false, but in no number, null, NaN or Infinity (those are
# numbers to the parser and reported as non-finite coordinates later).
_NOT_NUMBER = np.frombuffer(b"rs", dtype=np.uint8)


def _key_before(body: bytes, pos: int) -> str:
    """The member name written before position ``pos`` (``"points": [`` -> ``points``)."""
    end = body.rfind(b'"', 0, pos)
    start = body.rfind(b'"', 0, end) if end > 0 else -1
    return body[start + 1:end].decode("utf-8", "replace") if start >= 0 else ""


def member_rows(body: bytes, chunk: int = CHUNK_BYTES) -> dict[str, int]:
    """Arrays nested in each top-level member's array: ``{"points": n, "normals": n, ...}``.

    Parameters
    ----------
    body : bytes
        A JSON object such as ``{"points": [[x, y, z], ...], "params": {...}}``.
    chunk : int
        Bytes scanned at a time (bounds the scan's memory).
    """
    return scan_members(body, chunk)[0]


def scan_members(body: bytes, chunk: int = CHUNK_BYTES) -> tuple[dict[str, int], set[str]]:
    """:func:`member_rows`, and the top-level array members holding anything but numbers
    and ``null`` (``true``, ``false``, strings), which numpy would turn into numbers without
    a word (``false`` -> 0.0, ``"1"`` -> 1.0)."""
    counts: dict[str, int] = {}
    texty: set[str] = set()
    depth, in_string, escaped = 0, False, False
    current: str | None = None
    for offset in range(0, len(body), chunk):
        a = np.frombuffer(body, np.uint8, count=min(chunk, len(body) - offset), offset=offset)
        backslash = a == _BACKSLASH
        quote = a == _QUOTE
        quote[0] &= not escaped
        quote[1:] &= ~backslash[:-1]
        escaped = bool(backslash[-1])
        parity = np.cumsum(quote, dtype=np.int32)
        parity += in_string
        structural = (parity % 2 == 0) & ~quote
        in_string = bool(parity[-1] % 2)
        opens_list = (a == _OPEN_LIST) & structural
        opens = opens_list | ((a == _OPEN_OBJ) & structural)
        closes = ((a == _CLOSE_LIST) | (a == _CLOSE_OBJ)) & structural
        level = np.cumsum(opens.astype(np.int8) - closes.astype(np.int8), dtype=np.int32)
        level += depth
        depth = int(level[-1])
        rows = np.flatnonzero(opens_list & (level == 3))
        starts = np.flatnonzero(opens_list & (level == 2))
        ends = np.flatnonzero(closes & (level == 1))
        # Inside an array member: a quote, or a letter of true or false.
        odd = np.flatnonzero((level >= 2) & (quote | (structural & np.isin(a, _NOT_NUMBER))))
        # Walk the few member boundaries; rows between two of them belong to `current`.
        events = sorted([(int(p), 1) for p in starts] + [(int(p), 0) for p in ends])
        last = 0
        for position, is_start in events + [(len(a), -1)]:
            if current is not None:
                inside = np.searchsorted(rows, position) - np.searchsorted(rows, last)
                counts[current] = counts.get(current, 0) + int(inside)
                if np.searchsorted(odd, position) > np.searchsorted(odd, last):
                    texty.add(current)
            if is_start == 1:
                current = _key_before(body, offset + position)
                counts.setdefault(current, 0)
            elif is_start == 0:
                current = None
            last = position
    return counts, texty
