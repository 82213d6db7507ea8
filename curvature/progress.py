"""A dependency-free progress bar for long runs on stderr."""

from __future__ import annotations

import sys
import time


class ProgressBar:
    """Callable ``(done, total)`` that draws a bar once the run has lasted ``delay`` seconds.

    On a terminal the bar redraws in place; elsewhere (logs, CI) it prints a line every 10 %.

    Parameters
    ----------
    label : str
        Shown before the bar.
    stream : file-like
        Where to draw (stderr by default).
    delay : float
        Short runs finish before this and print nothing.
    """

    def __init__(self, label: str = "", stream=None, delay: float = 0.5):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.delay = delay
        self.start = time.perf_counter()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.last_draw = 0.0
        self.last_decile = -1
        self.drawn = False

    def __call__(self, done: int, total: int) -> None:
        now = time.perf_counter()
        elapsed = now - self.start
        if elapsed < self.delay and done < total:
            return
        frac = done / total if total else 1.0
        if self.tty:
            if now - self.last_draw < 0.1 and done < total:
                return
            width = 30
            filled = int(round(frac * width))
            eta = elapsed / frac - elapsed if frac > 0 else float("nan")
            text = (f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {frac:6.1%} "
                    f"{done}/{total} {elapsed:6.1f}s eta {eta:5.1f}s")
            self.stream.write(text)
            if done >= total:
                self.stream.write("\n")
        else:
            decile = int(frac * 10)
            if decile == self.last_decile:
                return
            self.last_decile = decile
            self.stream.write(f"{self.label} {frac:.0%} ({done}/{total}) {elapsed:.1f}s\n")
        self.stream.flush()
        self.last_draw = now
        self.drawn = True
