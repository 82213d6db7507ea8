"""A progress bar on stderr that follows a remote job's status and progress."""

from __future__ import annotations

import sys
import time


class JobProgressBar:
    """Draws ``job <id> <status> [#####.....] 45.0%  12.3s`` as a job advances.

    On a terminal the line is redrawn in place (at most 10 times a second); elsewhere (logs,
    CI) a line is printed when the status changes and at every further 10 % of progress.

    Parameters
    ----------
    job_id : str
        Shown at the start of the line.
    stream : file-like, optional
        Where to draw; stderr by default.
    """

    WIDTH = 30

    def __init__(self, job_id: str, stream=None):
        self.job_id = job_id
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.start = time.monotonic()
        self.last_draw = float("-inf")
        self.last_key: tuple[str, int] | None = None
        self.open_line = False

    def update(self, status: str, progress: float) -> None:
        """Show the job's latest state (``progress`` in 0..1)."""
        frac = min(max(float(progress), 0.0), 1.0)
        now = time.monotonic()
        filled = int(round(frac * self.WIDTH))
        text = (f"job {self.job_id} {status:<9} [{'#' * filled}{'.' * (self.WIDTH - filled)}] "
                f"{frac:6.1%} {now - self.start:6.1f}s")
        if self.tty:
            if now - self.last_draw < 0.1 and (status, int(frac * 1000)) == self.last_key:
                return
            self.stream.write("\r" + text)
            self.open_line = True
        else:
            key = (status, int(frac * 10))
            if key == self.last_key:
                return
            self.last_key = key
            self.stream.write(text + "\n")
        self.stream.flush()
        self.last_draw = now
        if self.tty:
            self.last_key = (status, int(frac * 1000))

    def close(self) -> None:
        """End the line drawn in place (call once the job is final)."""
        if self.open_line:
            self.stream.write("\n")
            self.stream.flush()
            self.open_line = False
