"""Text bodies read a block of whole lines at a time, so memory stays bounded.

Every text reader (XYZ/CSV, PCD ascii, OFF, OBJ, ascii STL, ascii PLY) walks its body in
blocks of about :data:`BLOCK_BYTES` cut after a newline. A block's temporaries (token
positions, per-line counts, the parsed numbers) are freed before the next block is read, so
the peak memory of a read is the file's bytes, the arrays returned and a few block-sized
scratch arrays, whatever the file's size (``benchmarks/soak.py`` measures it per format).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ..errors import FormatError

BLOCK_BYTES = 1 << 18
# No row of a point, vertex or face needs more; a longer line is refused rather than let one
# line make a block (and its scratch arrays) as large as the file.
MAX_LINE_BYTES = 1 << 20
_HASH, _NEWLINE = 35, 10


def line_blocks(data: bytes, start: int, stop: int | None = None, *, first_line: int = 1,
                source=None, block_bytes: int | None = None) -> Iterator[tuple[int, int, int]]:
    """Cut ``data[start:stop]`` into blocks of whole lines.

    Yields
    ------
    lo, hi : int
        Byte range of the block; ``hi`` is just after a newline, or ``stop``.
    first_line : int
        1-based file line number of the block's first line.

    Raises
    ------
    FormatError
        A line longer than :data:`MAX_LINE_BYTES` (names it).
    """
    stop = len(data) if stop is None else stop
    block_bytes = BLOCK_BYTES if block_bytes is None else block_bytes
    lo, line = start, first_line
    while lo < stop:
        hi = min(lo + block_bytes, stop)
        if hi < stop:
            cut = data.rfind(b"\n", lo, hi)
            if cut < 0:  # the line at lo is longer than a block
                cut = data.find(b"\n", hi, min(stop, lo + MAX_LINE_BYTES + 1))
            if cut >= 0:
                hi = cut + 1
            elif stop - lo <= MAX_LINE_BYTES:
                hi = stop
            else:
                raise FormatError(source, f"line longer than {MAX_LINE_BYTES} bytes",
                                  line=line)
        elif stop - max(lo, data.rfind(b"\n", lo, stop) + 1) > MAX_LINE_BYTES:
            raise FormatError(source, f"line longer than {MAX_LINE_BYTES} bytes",
                              line=line + data.count(b"\n", lo, stop))
        yield lo, hi, line
        line += data.count(b"\n", lo, hi)
        lo = hi


@dataclass
class Tokens:
    """Whitespace-separated tokens of one block (positions relative to the block).

    Attributes
    ----------
    line_ends : ndarray, shape (m,), int64
        Position of each line's newline (or the block's end for a last line without one).
    starts, ends : ndarray, shape (t,), int64
        First byte and one past the last byte of each token.
    line : ndarray, shape (t,), int64
        Line index (0 .. m-1) of each token.
    lens : ndarray, shape (m,), int64
        Tokens per line.
    """

    line_ends: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    line: np.ndarray
    lens: np.ndarray

    def first(self) -> np.ndarray:
        """Index into ``starts`` of each line's first token (lines with tokens only matter)."""
        return np.cumsum(self.lens) - self.lens


def tokenize(buf: bytes) -> Tokens:
    """Locate lines and tokens of a block: bytes <= 32 (blanks, tabs, CR, LF) separate."""
    raw = np.frombuffer(buf, dtype=np.uint8)
    line_ends = np.flatnonzero(raw == _NEWLINE)
    if raw.size and raw[-1] != _NEWLINE:
        line_ends = np.append(line_ends, raw.size)
    space = np.empty(raw.size + 2, dtype=np.int8)
    space[0] = space[-1] = 1
    np.less_equal(raw, 32, out=space[1:-1].view(np.bool_))
    edge = np.diff(space)
    del space
    starts = np.flatnonzero(edge == -1)
    ends = np.flatnonzero(edge == 1)
    del edge
    line = np.searchsorted(line_ends, starts)
    lens = np.bincount(line, minlength=line_ends.size).astype(np.int64, copy=False)
    return Tokens(line_ends, starts, ends, line, lens[:line_ends.size])


def check_utf8(buf: bytes, source, offset: int) -> None:
    """Refuse a block that is not UTF-8 text, naming the byte (``offset`` = block start)."""
    if not buf.isascii():
        try:
            buf.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FormatError(source, f"not a text file: byte 0x{buf[exc.start]:02x} is not "
                                      "valid UTF-8", offset=offset + exc.start) from None


def blank_ranges(buf: bytes, lo: np.ndarray, hi: np.ndarray) -> bytes:
    """``buf`` with the disjoint byte ranges ``[lo[i], hi[i])`` overwritten by blanks."""
    if lo.size == 0:
        return buf
    delta = np.zeros(len(buf) + 1, dtype=np.int8)
    np.add.at(delta, lo, 1)
    np.add.at(delta, hi, -1)
    out = np.frombuffer(bytearray(buf), dtype=np.uint8)
    out[np.cumsum(delta[:-1], dtype=np.int8) > 0] = 32
    return out.tobytes()


def blank_comments(buf: bytes, *, anywhere: bool) -> bytes:
    """Blank ``#`` comments: whole lines whose first token starts with ``#``, or (with
    ``anywhere``) everything from a line's first ``#`` to its end."""
    if b"#" not in buf:
        return buf
    raw = np.frombuffer(buf, dtype=np.uint8)
    hashes = np.flatnonzero(raw == _HASH)
    line_ends = np.flatnonzero(raw == _NEWLINE)
    line = np.searchsorted(line_ends, hashes)
    first = np.ones(hashes.size, dtype=bool)
    first[1:] = line[1:] != line[:-1]  # only the first '#' of a line matters
    hashes, line = hashes[first], line[first]
    if not anywhere:
        line_start = np.where(line > 0, line_ends[np.maximum(line - 1, 0)] + 1, 0)
        before = np.concatenate(([0], np.cumsum(raw > 32, dtype=np.int64)))
        leading = before[hashes] == before[line_start]  # nothing but blanks before it
        hashes, line = hashes[leading], line[leading]
    ends = np.append(line_ends, raw.size)[line]
    return blank_ranges(buf, hashes, ends)


def parse_floats(buf: bytes, count: int, source, line_of: Callable[[int], int], *,
                 expected: str = "a number") -> np.ndarray:
    """All ``count`` whitespace-separated numbers of ``buf`` as float64.

    numpy's C parser reads the whole block in one call; only when it stops early (a token
    that is not a number) are the lines split in Python, to name the token and its line.

    Parameters
    ----------
    line_of : callable
        Maps a 0-based line index within ``buf`` to the file's line number.
    expected : str
        What a token should have been, for the message (``"an integer"``).

    Raises
    ------
    FormatError
        A token is not a number (names it and its line).
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            values = np.fromstring(buf, dtype=np.float64, sep=" ")
        if values.size == count:
            return values
    except (ValueError, DeprecationWarning):
        pass
    for i, line in enumerate(buf.decode("latin-1").split("\n")):
        for tok in line.split():
            try:
                float(tok.replace("_", "!"))  # float() takes "1_0"; numpy's parser does not
            except ValueError:
                shown = tok if len(tok) <= 40 else tok[:37] + "..."
                raise FormatError(source, f"{shown!r} is not {expected}",
                                  line=line_of(i)) from None
    raise FormatError(source, f"a value is not {expected}")  # pragma: no cover - defensive


def gather(buf: bytes, lo: np.ndarray, hi: np.ndarray) -> bytes:
    """The byte ranges ``[lo[i], hi[i])`` of ``buf``, one a line (for parsing them alone)."""
    if lo.size == 0:
        return b""
    raw = np.frombuffer(buf, dtype=np.uint8)
    size = hi - lo + 1
    out = np.full(int(size.sum()), _NEWLINE, dtype=np.uint8)
    at = np.cumsum(size) - size
    within = np.arange(out.size, dtype=np.int64) - np.repeat(at, size)
    keep = within < np.repeat(size - 1, size)
    out[keep] = raw[(np.repeat(lo, size) + within)[keep]]
    return out.tobytes()


@dataclass
class RowBlock:
    """One block of a row-per-line body.

    Attributes
    ----------
    first_line : int
        File line number of the block's first line.
    offset : int
        Byte offset of the block in the file.
    buf : bytes
        The block's bytes, prepared (separators and comments blanked).
    tokens : Tokens
    rows : ndarray, shape (r,), int64
        Line indices (within the block) of the non-blank lines, in order.
    """

    first_line: int
    offset: int
    buf: bytes
    tokens: Tokens
    rows: np.ndarray


class RowScanner:
    """Walks the non-blank lines of ``data[start:]`` block by block.

    Parameters
    ----------
    prepare : callable, optional
        ``bytes -> bytes`` applied to every block before tokenizing (same length: replace
        separators, blank comments).
    """

    def __init__(self, data: bytes, start: int, first_line: int, source,
                 prepare: Callable[[bytes], bytes] | None = None):
        self.data, self.start, self.first_line = data, start, first_line
        self.source, self.prepare = source, prepare
        self.end, self.end_line, self.rows_seen = start, first_line, 0

    def blocks(self, max_rows: int | None = None) -> Iterator[RowBlock]:
        """Blocks from ``start`` until the end of the data or ``max_rows`` non-blank lines
        (the last block is cut after the line of the last row). Afterwards ``end`` and
        ``end_line`` say where the walk stopped and ``rows_seen`` how many rows it found."""
        seen = 0
        self.end, self.end_line = self.start, self.first_line
        for lo, hi, first in line_blocks(self.data, self.start, first_line=self.first_line,
                                         source=self.source):
            raw = self.data[lo:hi]
            check_utf8(raw, self.source, lo)
            buf = self.prepare(raw) if self.prepare is not None else raw
            tok = tokenize(buf)
            rows = np.flatnonzero(tok.lens)
            if max_rows is not None and seen + rows.size >= max_rows:
                rows = rows[:max_rows - seen]
                cut = int(tok.line_ends[rows[-1]]) + 1 if rows.size else 0
                buf = buf[:cut]
                tok = tokenize(buf)
                hi = lo + cut
            seen += rows.size
            self.end, self.end_line, self.rows_seen = hi, first + tok.line_ends.size, seen
            if rows.size:
                yield RowBlock(first, lo, buf, tok, rows)
            if max_rows is not None and seen >= max_rows:
                break
        self.rows_seen = seen

    def line_of_row(self, row: int, max_rows: int | None = None) -> int:
        """File line of the ``row``-th non-blank line (0-based); for error messages."""
        seen = 0
        for block in self.blocks(max_rows):
            if row < seen + block.rows.size:
                return block.first_line + int(block.rows[row - seen])
            seen += block.rows.size
        raise IndexError(row)  # pragma: no cover - callers pass rows that exist


def rows_values(block: RowBlock, source) -> np.ndarray:
    """Every number of a block's rows, flat, in order (float64)."""
    return parse_floats(block.buf, int(block.tokens.lens.sum()), source,
                        lambda i: block.first_line + i)


def separator_table(sep: str | None) -> Callable[[bytes], bytes] | None:
    """A ``prepare`` turning ``sep`` into blanks (semicolon files: decimal commas to
    points first)."""
    if sep == ";":
        table = bytes.maketrans(b",;", b". ")
    elif sep == ",":
        table = bytes.maketrans(b",", b" ")
    else:
        return None
    return lambda buf: buf.translate(table)
