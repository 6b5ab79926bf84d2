"""A dependency-free progress bar for long CLI runs (written to stderr).

On a terminal it redraws one line; elsewhere (CI logs, pipes) it prints one line per finished
item so logs stay readable.  ``quiet`` silences it.
"""

from __future__ import annotations

import sys
import time


class Progress:
    """``Progress(total, label)``; call :meth:`advance` once per finished item, :meth:`close` at
    the end."""

    def __init__(self, total: int, label: str = "", *, quiet: bool = False, stream=None, width: int = 30,
                 percent: bool = False):
        self.total = max(int(total), 0)
        self.percent = percent  # show "25%" (work measured as a fraction) rather than "25/100"
        self.label = label
        self.quiet = quiet
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.done = 0
        self.start = time.monotonic()
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        if self.tty and not quiet:
            self._draw("")

    def _elapsed(self) -> str:
        s = int(time.monotonic() - self.start)
        return f"{s // 3600:d}:{s // 60 % 60:02d}:{s % 60:02d}"

    def _draw(self, note: str) -> None:
        frac = self.done / self.total if self.total else 1.0
        filled = int(round(frac * self.width))
        bar = "#" * filled + "." * (self.width - filled)
        line = f"\r{self.label} [{bar}] {self._count()} {self._elapsed()} {note}"
        self.stream.write(line[:200].ljust(120))
        self.stream.flush()

    def _count(self) -> str:
        if self.percent:
            return f"{100 * self.done // max(self.total, 1)}%"
        return f"{self.done}/{self.total}"

    def advance(self, note: str = "", n: int = 1) -> None:
        self.done += n
        if self.quiet:
            return
        if self.tty:
            self._draw(note)
        else:
            self.stream.write(f"{self.label} [{self._count()}] {self._elapsed()} {note}\n")
            self.stream.flush()

    def update_fraction(self, fraction: float, note: str = "") -> None:
        """For work measured as a fraction in [0, 1] (``total`` should then be 100).  Off a
        terminal it writes a line only when another tenth is complete, so logs stay short."""
        done = int(round(min(max(float(fraction), 0.0), 1.0) * self.total))
        if self.quiet or done == self.done:
            return
        crossed = done * 10 // max(self.total, 1) != self.done * 10 // max(self.total, 1)
        self.done = done
        if self.tty:
            self._draw(note)
        elif crossed:
            self.stream.write(f"{self.label} [{self._count()}] {self._elapsed()} {note}\n")
            self.stream.flush()

    def close(self) -> None:
        if self.tty and not self.quiet:
            self.stream.write("\n")
            self.stream.flush()
