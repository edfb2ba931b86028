"""A tiny progress bar on stderr (no dependency): ``[#####.....] 52% pour  1920/3700 12.3 s``.

Redraws at most ``hz`` times a second; on a non-terminal stream it prints one line per phase
change instead of carriage-return redraws, so logs stay readable.
"""
from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    """Progress over ``total`` units. ``update(n, label)`` advances; ``close()`` ends the line.

    ``enabled=False`` makes every call a no-op (tests, library use).
    """

    def __init__(self, total, desc="", stream=None, enabled=True, width=30, hz=8.0):
        if int(total) < 0:
            raise ValueError(f"total must be >= 0, got {total!r}")
        self.total = int(total)
        self.desc = desc
        self.stream = sys.stderr if stream is None else stream
        self.enabled = bool(enabled)
        self.width = int(width)
        self.period = 1.0 / float(hz)
        self.done = 0
        self.label = ""
        self.t0 = time.perf_counter()
        self._last = -1.0
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def update(self, n=1, label=None):
        self.done = min(self.total, self.done + int(n))
        changed = label is not None and label != self.label
        if label is not None:
            self.label = label
        if not self.enabled:
            return
        now = time.perf_counter()
        if self._tty and (now - self._last >= self.period or self.done == self.total):
            self._last = now
            self.stream.write("\r" + self._line(now))
            self.stream.flush()
        elif not self._tty and changed:
            self.stream.write(self._line(now) + "\n")
            self.stream.flush()

    def _line(self, now):
        frac = self.done / self.total if self.total else 1.0
        fill = int(round(frac * self.width))
        return (f"{self.desc}[{'#' * fill}{'.' * (self.width - fill)}] {100 * frac:3.0f}% "
                f"{self.label:<7s} {self.done}/{self.total} {now - self.t0:6.1f} s")

    def close(self):
        if self.enabled:
            self.stream.write(("\r" if self._tty else "") + self._line(time.perf_counter()) + "\n")
            self.stream.flush()
