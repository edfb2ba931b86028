"""The progress bar of long runs (pour, pack): tqdm behind a small, stable interface.

``Progress(total, desc, enabled=...)``, ``update(n, label)``, ``close()`` is what the pour and
the packing protocols call; the bar itself is tqdm's, so it looks like every other Python tool
and shows the rate and the time left (``[elapsed<remaining]``). ``label`` (the protocol phase)
is shown after the counts. On a stream that is not a terminal (a log file, CI) the bar redraws
at most every ``log_interval`` seconds instead of ``hz`` times a second, so logs stay short.
``enabled=False`` (``progress=False`` in the callers) writes nothing at all.

First-run honesty: on a cold Numba cache the first step compiles for minutes, which tqdm would
average into an ETA of hours. ``note`` (say, "compiling the DEM kernels (first run only)")
is written once before the bar, and the bar's clock and rate restart after the first step, so
the time left and the rate are those of the stepping. ``first_seconds`` is the first step's
wall-clock (compilation included) for callers that report rates without it.
"""
from __future__ import annotations

import sys
import time

from tqdm import tqdm

from peclet.core.validation import check_bool, check_float, check_int

__all__ = ["Progress", "ms_per_step", "compile_note"]

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
                 log_interval=30.0, initial=0, note=None):
        self.total = check_int("total", total, 0)
        self.enabled = check_bool("enabled", enabled)
        hz = check_float("hz", hz, 0.0, lo_open=True)
        log_interval = check_float("log_interval", log_interval, 0.0)
        self.desc = str(desc)
        self.stream = sys.stderr if stream is None else stream
        self.done = check_int("initial", initial, 0, self.total)
        self.label = ""
        #: wall-clock (s) from construction to the first update that advances (None before)
        self.first_seconds = None
        self._t0 = time.perf_counter()
        if self.enabled and note:
            self.stream.write(str(note).rstrip("\n") + "\n")
            self.stream.flush()
        tty = bool(getattr(self.stream, "isatty", lambda: False)())
        head = self.desc.strip()
        self._bar = tqdm(total=self.total, desc=head + ": " if head else "", file=self.stream,
                         disable=not self.enabled, ncols=None if width is None else int(width),
                         dynamic_ncols=width is None and tty, ascii=not tty,
                         mininterval=1.0 / hz if tty else log_interval,
                         bar_format=_FORMAT + ("" if tty else "\n"), unit="step",
                         leave=True, initial=self.done)

    def update(self, n=1, label=None):
        step = min(self.total - self.done, int(n))
        self.done += step
        if label is not None and label != self.label:
            self.label = str(label)
            self._bar.set_postfix_str(self.label, refresh=False)
        self._bar.update(step)
        if self.first_seconds is None and step > 0:
            self.first_seconds = time.perf_counter() - self._t0
            self._restart_clock()

    def _restart_clock(self):
        # tqdm's rate is a moving average that a minutes-long first step (compilation) would
        # dominate for a long time: start the clock and the averages again from here
        b = self._bar
        if b.disable:
            return
        b.reset(total=self.total)
        b.initial = b.n = b.last_print_n = self.done
        b.refresh()

    def close(self):
        self._bar.close()


def ms_per_step(seconds, first_step_seconds, steps):
    """Milliseconds per step of a stepping loop that took ``seconds`` for ``steps`` steps,
    leaving out the first step (``first_step_seconds``: on a cold cache it holds the kernels'
    compilation, which is not a stepping rate); the whole average when there was one step."""
    if steps > 1:
        return 1e3 * (seconds - first_step_seconds) / (steps - 1)
    return 1e3 * seconds / max(steps, 1)


def compile_note():
    """The line a run prints before its first step when the DEM kernels are not in Numba's
    cache yet (else None)."""
    from peclet.dem.simulation import step_kernels_cached

    if step_kernels_cached() is False:
        return ("compiling the DEM kernels (first run only: about 2 minutes on 2 cores; Numba "
                "caches them for every later run)")
    return None
