"""The progress bar of long runs (pour, pack): tqdm behind a small, stable interface.

``Progress(total, desc, enabled=...)``, ``update(n, label)``, ``close()`` is what the pour and
the packing protocols call; the bar itself is tqdm's, so it looks like every other Python tool
and shows the rate and the time left (``[elapsed<remaining]``). ``label`` (the protocol phase)
is shown after the counts. On a stream that is not a terminal (a log file, CI) the bar redraws
at most every ``log_interval`` seconds instead of ``hz`` times a second, so logs stay short.
``enabled=False`` (``progress=False`` in the callers) writes nothing at all.
"""
from __future__ import annotations

import sys

from tqdm import tqdm

from peclet.core.validation import check_bool, check_float, check_int

__all__ = ["Progress"]

#: tqdm's layout with the time left always shown (``remaining``) and the phase label last.
_FORMAT = "{desc}{percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}, " \
          "{rate_fmt}]{postfix}"


class Progress:
    """Progress over ``total`` units (steps). ``update(n, label)`` advances by ``n`` and, if
    given, sets the phase ``label``; ``close()`` ends the line.

    ``desc`` is printed before the bar; ``stream`` defaults to ``sys.stderr``; ``hz`` is the
    redraw rate on a terminal, ``log_interval`` (seconds) the one elsewhere; ``width`` the bar's
    character width (None: fit the terminal). Counts past ``total`` are clamped.
    """

    def __init__(self, total, desc="", stream=None, enabled=True, width=None, hz=8.0,
                 log_interval=30.0):
        self.total = check_int("total", total, 0)
        self.enabled = check_bool("enabled", enabled)
        hz = check_float("hz", hz, 0.0, lo_open=True)
        log_interval = check_float("log_interval", log_interval, 0.0)
        self.desc = str(desc)
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        self.label = ""
        tty = bool(getattr(self.stream, "isatty", lambda: False)())
        head = self.desc.strip()
        self._bar = tqdm(total=self.total, desc=head + ": " if head else "", file=self.stream,
                         disable=not self.enabled, ncols=None if width is None else int(width),
                         dynamic_ncols=width is None and tty, ascii=not tty,
                         mininterval=1.0 / hz if tty else log_interval,
                         bar_format=_FORMAT + ("" if tty else "\n"), unit="step",
                         leave=True)

    def update(self, n=1, label=None):
        step = min(self.total - self.done, int(n))
        self.done += step
        if label is not None and label != self.label:
            self.label = str(label)
            self._bar.set_postfix_str(self.label, refresh=False)
        self._bar.update(step)

    def close(self):
        self._bar.close()
