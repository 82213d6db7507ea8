"""Error types raised for bad global input.

Every error is a ``ValueError`` subclass so callers can catch one type; the message always
says what was wrong and, for files, where (file name, line or byte offset).
"""

from __future__ import annotations

import os


class CurvatureInputError(ValueError):
    """Bad global input: empty cloud, non-finite coordinates, wrong shape, too few points."""


class ParameterError(CurvatureInputError):
    """A method or fit parameter is out of range or inconsistent with another one."""


class FormatError(CurvatureInputError):
    """A file could not be read or written in the format it claims.

    Parameters
    ----------
    path : str or os.PathLike or None
        The file concerned (``None`` for in-memory buffers).
    message : str
        What was wrong, e.g. ``"header says 1000 vertices but the body holds 812"``.
    line : int, optional
        1-based line number for text formats.
    offset : int, optional
        Byte offset for binary formats.
    """

    def __init__(self, path, message: str, *, line: int | None = None,
                 offset: int | None = None):
        self.path = None if path is None else os.fspath(path)
        self.reason = message
        self.line = line
        self.offset = offset
        where = []
        if line is not None:
            where.append(f"line {line}")
        if offset is not None:
            where.append(f"byte {offset}")
        prefix = self.path if self.path is not None else "<buffer>"
        if where:
            prefix += " (" + ", ".join(where) + ")"
        super().__init__(f"{prefix}: {message}")


class UnknownFormatError(FormatError):
    """The file extension or declared format is not one the library reads or writes."""


class TooFewPointsError(FormatError):
    """The file holds no points, or fewer than the 10 a curvature estimate needs."""


class NonFiniteError(FormatError):
    """A point of the file has a NaN or infinite coordinate."""
