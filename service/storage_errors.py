"""Recognising a full disk, a read-only store and a locked one, wherever the error is raised.

Web-free: the server maps these to 507 and 503 answers, the workers to a failed job. Both
kinds leave nothing half-done behind (files are written to a temporary name and renamed,
store changes are transactions), so a clear answer is all that is needed.
"""

from __future__ import annotations

import errno
import sqlite3

from .problem_types import ProblemError

_NO_SPACE = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
_READ_ONLY = {errno.EROFS}


def storage_problem(exc: BaseException, doing: str) -> ProblemError | None:
    """The problem to report for ``exc``, or ``None`` when it is no storage error.

    Parameters
    ----------
    exc : BaseException
        The exception raised.
    doing : str
        What was being done, for the message (e.g. ``"storing the upload"``).
    """
    if isinstance(exc, OSError) and exc.errno in _NO_SPACE:
        return ProblemError("insufficient-storage",
                            f"no space left on the server's disk while {doing}; nothing was "
                            "kept. Retry later.")
    if isinstance(exc, OSError) and exc.errno in (errno.EMFILE, errno.ENFILE):
        return ProblemError("queue-full", f"the server has too many open files while {doing}; "
                            "nothing was kept. Retry later.")
    if isinstance(exc, OSError) and exc.errno in _READ_ONLY:
        return ProblemError("store-read-only", f"the server's data folder is read-only while "
                            f"{doing}; nothing was kept. Retry later.")
    if isinstance(exc, sqlite3.OperationalError):
        name = getattr(exc, "sqlite_errorname", "") or ""
        text = str(exc).lower()
        if name.startswith("SQLITE_FULL") or "disk is full" in text:
            return ProblemError("insufficient-storage",
                                f"the job store's disk is full while {doing}; nothing was "
                                "changed. Retry later.")
        if name.startswith("SQLITE_READONLY") or "readonly database" in text:
            return ProblemError("store-read-only", f"the job store cannot be written while "
                                f"{doing}; nothing was changed. Retry later.")
        if name.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")) or "database is locked" in text:
            return ProblemError("store-busy", f"the job store stayed locked while {doing}; "
                                "nothing was changed. Retry later.")
    return None
